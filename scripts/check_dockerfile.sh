#!/usr/bin/env bash
# Checks deploy/docker/Dockerfile without Docker, against a built tree (CI runs it after the
# build):
#   a. the build stage is FROM debian:12, runs exactly `bash scripts/install_deps.sh --serve` and
#      one `RECOG_CMAKE_ARGS="..." bash scripts/build.sh` (no other cmake call), and every file it
#      COPYs exists: from the build context (the repository), and from the build stage (mapped
#      back to the repository and BUILD_DIR);
#   b. the CMake arguments are exactly -DCMAKE_BUILD_TYPE=Release -DRECOG_BUILD_TESTS=OFF
#      -DRECOG_BUILD_BENCHMARKS=OFF, each RECOG_* an option() of the top-level CMakeLists.txt;
#   c. every shared library that ldd resolves for BUILD_DIR/bin/recogd, BUILD_DIR/bin/recog and
#      recog's video module (BUILD_DIR/lib/recog/librecog_video.so, copied where recog finds it:
#      /usr/local/lib/recog/ beside /usr/local/bin/recog)
#      belongs (dpkg -S) to a package the runtime stage (FROM debian:12-slim) installs or to one
#      of their dependencies (apt-cache depends --recurse: local package lists, no network);
#   d. the runtime stage runs as a USER other than root and has a HEALTHCHECK.
# Prints one line per failure and exits 1, or prints a one-line summary.
#
# Usage: bash scripts/check_dockerfile.sh [BUILD_DIR]   (default: build)
set -euo pipefail
export LC_ALL=C  # one collation for sort, comm and the error messages
cd "$(dirname "$0")/.."
build_dir=${1:-build}
build_dir=${build_dir%/}
dockerfile=deploy/docker/Dockerfile

failures=0
fail() {
  echo "check_dockerfile: $*" >&2
  failures=$((failures + 1))
}

[ -f "$dockerfile" ] || { echo "check_dockerfile: $dockerfile not found" >&2; exit 1; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# One instruction per line, continuations joined, comments dropped, blanks squeezed:
# "<stage number>\t<INSTRUCTION> <arguments>", stages numbered from 1 by their FROM.
instructions=$(awk '
  /^[[:space:]]*#/ || /^[[:space:]]*$/ { next }
  {
    line = $0
    if (sub(/\\[[:space:]]*$/, "", line)) { buf = buf line " "; next }
    buf = buf line
    gsub(/[[:space:]]+/, " ", buf); sub(/^ /, "", buf); sub(/ $/, "", buf)
    split(buf, w, " ")
    if (toupper(w[1]) == "FROM") stage++
    print stage "\t" buf
    buf = ""
  }' "$dockerfile")
stages=$(awk -F'\t' 'END { print $1 + 0 }' <<<"$instructions")
if [ "$stages" -lt 2 ]; then
  echo "check_dockerfile: $dockerfile needs a build and a runtime stage, found $stages stage(s)" >&2
  exit 1
fi
stage() { awk -F'\t' -v s="$1" '$1 == s { print $2 }' <<<"$instructions"; }
build_stage=$(stage 1)
runtime_stage=$(stage "$stages")

# --- a. build stage: base image, install and build commands, copied files -----------------------
read -r _ build_image _ build_name <<<"$(grep -m1 '^FROM ' <<<"$build_stage")"
[ "$build_image" = debian:12 ] || fail "build stage: FROM must be debian:12, got '$build_image'"
grep -qx 'RUN bash scripts/install_deps.sh --serve' <<<"$build_stage" ||
  fail "build stage: missing the line 'RUN bash scripts/install_deps.sh --serve'"
build_re='^RUN RECOG_CMAKE_ARGS="([^"]*)" bash scripts/build\.sh$'
build_lines=$(grep -cE "$build_re" <<<"$build_stage" || true)
[ "$build_lines" -eq 1 ] ||
  fail "build stage: needs one 'RUN RECOG_CMAKE_ARGS=... bash scripts/build.sh', found $build_lines"
if grep -E '^RUN ' <<<"$build_stage" | grep -qE '(^RUN |[;&|(] *)cmake( |$)'; then
  fail "build stage: calls cmake directly; the one build command is scripts/build.sh"
fi
grep -q 'RECOG_CMAKE_ARGS' scripts/build.sh ||
  fail "scripts/build.sh no longer reads RECOG_CMAKE_ARGS"
workdir=$(grep '^WORKDIR ' <<<"$build_stage" | tail -1 | cut -d' ' -f2 || true)
workdir=${workdir:-/}

# The sources of a COPY/ADD instruction (every argument but the last, flags dropped).
copy_sources() {
  local args words
  args=$(sed -E 's/^(COPY|ADD) //; s/(^| )--[a-z]+(=[^ ]*)?//g; s/^ //' <<<"$1")
  if [[ $args == \[* ]]; then args=$(tr -d '[],"' <<<"$args"); fi
  read -r -a words <<<"$args"
  [ ${#words[@]} -ge 2 ] || return 0
  printf '%s\n' "${words[@]:0:${#words[@]}-1}"
}
exists() { compgen -G "$1" >/dev/null; }  # a path or a glob with at least one match
# The .dockerignore pattern that keeps `$1` (or a folder above it) out of the build context.
ignored_by() {
  local pattern prefix=$1
  [ -f .dockerignore ] || return 1
  while [ "$prefix" != . ] && [ -n "$prefix" ]; do
    while read -r pattern; do
      pattern=${pattern#/}
      pattern=${pattern%/}
      case $pattern in ""|"#"*|"!"*) continue ;; esac
      # shellcheck disable=SC2053  # the pattern is a glob on purpose
      if [[ $prefix == $pattern ]]; then echo "$pattern"; return 0; fi
    done <.dockerignore
    prefix=$(dirname "$prefix")
  done
  return 1
}

copies=0
while IFS= read -r line; do
  [ -n "$line" ] || continue
  from=$(grep -oE -- '--from=[^ ]+' <<<"$line" | cut -d= -f2 || true)
  while IFS= read -r src; do
    copies=$((copies + 1))
    if [ -z "$from" ]; then
      exists "$src" || fail "COPY source '$src' does not exist in the build context"
      if pattern=$(ignored_by "$src"); then
        fail "COPY source '$src' is excluded from the build context by .dockerignore ('$pattern')"
      fi
    elif [ "$from" = "$build_name" ] || [ "$from" = 0 ]; then
      case $src in
        "${workdir%/}"/*) rel=${src#"${workdir%/}"/} ;;
        *) fail "COPY --from=$from source '$src' is outside the build stage's WORKDIR $workdir"
           continue ;;
      esac
      case $rel in build/*) local_path=$build_dir/${rel#build/} ;; *) local_path=$rel ;; esac
      exists "$local_path" ||
        fail "COPY --from=$from source '$src' ($local_path here) does not exist"
    else
      fail "COPY --from=$from: not the build stage ('$build_name')"
    fi
  done < <(copy_sources "$line")
done < <(awk -F'\t' '$2 ~ /^(COPY|ADD) / { print $2 }' <<<"$instructions")

# --- b. CMake arguments --------------------------------------------------------------------------
cmake_args=$(sed -nE "s#$build_re#\\1#p" <<<"$build_stage" | head -1)
expected="-DCMAKE_BUILD_TYPE=Release -DRECOG_BUILD_BENCHMARKS=OFF -DRECOG_BUILD_TESTS=OFF"
given=$(tr ' ' '\n' <<<"$cmake_args" | sed '/^$/d' | sort | tr '\n' ' ')
[ "${given% }" = "$expected" ] ||
  fail "build stage: CMake arguments must be exactly '$expected' (any order), got '$cmake_args'"
for arg in $cmake_args; do
  name=${arg#-D}
  name=${name%%=*}
  case $name in
    CMAKE_BUILD_TYPE) ;;
    RECOG_*) grep -qE "^option\\(${name}[ )]" CMakeLists.txt ||
               fail "CMake argument $arg: $name is not an option() of CMakeLists.txt" ;;
    *) fail "CMake argument $arg: not a RECOG_* option nor CMAKE_BUILD_TYPE" ;;
  esac
done

# --- c. runtime libraries ------------------------------------------------------------------------
read -r _ runtime_image _ <<<"$(grep -m1 '^FROM ' <<<"$runtime_stage")"
[ "$runtime_image" = debian:12-slim ] ||
  fail "runtime stage: FROM must be debian:12-slim, got '$runtime_image'"
# The words after "apt-get install" up to the end of that command, options dropped.
mapfile -t runtime_packages < <(grep '^RUN .*apt-get install' <<<"$runtime_stage" |
  sed -E 's/.*apt-get install//; s/(&&|;|\|).*//' | tr ' ' '\n' | grep -vE '^(-.*)?$' | sort -u)
libraries=0
if [ ${#runtime_packages[@]} -eq 0 ]; then
  fail "runtime stage: no 'apt-get install' of runtime packages"
else
  # One apt-cache call for all packages: without a saved cache, each call parses the lists.
  { apt-cache show --no-all-versions "${runtime_packages[@]}" 2>/dev/null || true; } |
    sed -n 's/^Package: //p' | sort -u >"$tmp/known"
  while read -r p; do
    fail "runtime stage: package '$p' is unknown to apt-cache"
  done < <(printf '%s\n' "${runtime_packages[@]}" | comm -23 - "$tmp/known")
  # The packages and everything they depend on (alternatives and providers of virtual packages
  # included: any of them provides the library).
  { apt-cache depends --recurse --no-recommends --no-suggests --no-conflicts --no-breaks \
      --no-replaces --no-enhances "${runtime_packages[@]}" 2>/dev/null || true; } |
    sed -E 's/^[ |]*(Pre)?Depends: //; s/^ +//; s/[<>]//g; s/:[a-z0-9]+$//' |
    sort -u >"$tmp/allowed"

  libs=()
  for file in bin/recogd bin/recog lib/recog/librecog_video.so; do
    if [ ! -f "$build_dir/$file" ]; then
      fail "$build_dir/$file not found (build first)"
      continue
    fi
    while read -r name; do fail "$file: library $name not found by ldd"; done < <(
      ldd "$build_dir/$file" | awk '/not found/ { print $1 }')
    mapfile -t -O ${#libs[@]} libs < <(ldd "$build_dir/$file" |
      awk '$2 == "=>" && $3 ~ /^\// { print $3 } $1 ~ /^\// && $2 ~ /^\(0x/ { print $1 }')
  done
  mapfile -t libs < <(printf '%s\n' "${libs[@]}" | grep -E '^/(usr/)?lib(64)?/' | sort -u)
  libraries=${#libs[@]}
  if [ "$libraries" -gt 0 ]; then
    # Merged /usr: dpkg knows a file under /lib or under /usr/lib, by the symlink ldd names or by
    # the file it points to; look all four spellings up in one dpkg -S call.
    mapfile -t targets < <(readlink -f "${libs[@]}")
    for i in "${!libs[@]}"; do
      for c in "${libs[i]}" "${targets[i]}"; do
        case $c in /usr/*) other=${c#/usr} ;; *) other=/usr$c ;; esac
        printf '%s\t%s\n%s\t%s\n' "${libs[i]}" "$c" "${libs[i]}" "$other"
      done
    done >"$tmp/candidates"
    cut -f2 "$tmp/candidates" | sort -u | xargs -r dpkg -S 2>/dev/null |
      grep -E '^[^ ]+(, [^ ]+)*: /' >"$tmp/owners" || true
    # Prints "none<TAB>library" or "outside<TAB>library<TAB>package" for each library at fault.
    awk -F'\t' '
      FILENAME == ARGV[1] { allowed[$1] = 1; next }
      FILENAME == ARGV[2] {
        n = index($0, ": /")
        owner[substr($0, n + 2)] = substr($0, 1, n - 1)
        next
      }
      !($1 in seen) { seen[$1] = 1; order[++count] = $1 }
      !($1 in found) && ($2 in owner) { found[$1] = owner[$2] }
      END {
        for (i = 1; i <= count; i++) {
          lib = order[i]
          if (!(lib in found)) { print "none\t" lib; continue }
          k = split(found[lib], packages, /, /)
          ok = 0
          for (j = 1; j <= k; j++) {
            sub(/:.*/, "", packages[j])
            if (packages[j] in allowed) ok = 1
          }
          if (!ok) print "outside\t" lib "\t" packages[1]
        }
      }' "$tmp/allowed" "$tmp/owners" "$tmp/candidates" >"$tmp/faults"
    while IFS=$'\t' read -r kind lib package; do
      if [ "$kind" = none ]; then
        fail "library $lib belongs to no installed Debian package"
      else
        fail "library $lib (package $package) is neither installed by the runtime stage" \
          "nor a dependency of its packages"
      fi
    done <"$tmp/faults"
  fi
fi

# recog loads its video module from ../lib/recog/ beside its own folder (tools/evaluation).
grep -qE '^COPY --from=[^ ]+ ([^ ]+ )*/src/build/lib/recog/librecog_video\.so( [^ ]+)* /usr/local/lib/recog/$' \
  <<<"$runtime_stage" ||
  fail "runtime stage: recog's video module is not copied to /usr/local/lib/recog/ (recog is in /usr/local/bin)"

# --- d. runtime user and health check ------------------------------------------------------------
user=$(grep '^USER ' <<<"$runtime_stage" | tail -1 | cut -d' ' -f2 | cut -d: -f1 || true)
case $user in
  "") fail "runtime stage: no USER (it would run as root)" ;;
  root|0) fail "runtime stage: USER is $user" ;;
  *[!0-9]*) grep -qE "^RUN .*useradd .*[ ]$user( |$)" <<<"$runtime_stage" ||
              fail "runtime stage: USER $user is not created there (useradd)" ;;
esac
health=$(grep '^HEALTHCHECK ' <<<"$runtime_stage" | tail -1 || true)
if [ -z "$health" ] || [ "$health" = "HEALTHCHECK NONE" ]; then
  fail "runtime stage: no HEALTHCHECK"
fi

if [ $failures -gt 0 ]; then
  echo "check_dockerfile: $failures problem(s) in $dockerfile" >&2
  exit 1
fi
echo "check_dockerfile: ok ($copies copied files exist, CMake args valid, $libraries libraries" \
  "from ${#runtime_packages[@]} runtime packages and their dependencies, user $user, health check)"

#!/usr/bin/env bash
# docs/places.md's settings table is generated: the lines between its two marker comments must be
# exactly what `recog settings --markdown` prints. Fails with the difference otherwise; to update
# the docs, replace those lines by the command's output.
#
# Usage: settings_docs_test.sh RECOG SOURCE_DIR
set -euo pipefail
recog=$1
doc=$2/docs/places.md
begin='<!-- settings table: recog settings --markdown -->'
end='<!-- end of settings table -->'

for marker in "$begin" "$end"; do
  count=$(grep -cxF -- "$marker" "$doc" || true)
  if [ "$count" != 1 ]; then
    echo "FAIL: $doc has the line '$marker' $count times, not once" >&2
    exit 1
  fi
done
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
awk -v begin="$begin" -v end="$end" '$0 == end { inside = 0 } inside { print } $0 == begin { inside = 1 }' \
  "$doc" >"$tmp/documented.md"
"$recog" settings --markdown >"$tmp/generated.md"
if ! diff -u "$tmp/documented.md" "$tmp/generated.md"; then
  echo "FAIL: $doc's settings table differs from 'recog settings --markdown' (above: - docs, + generated)" >&2
  exit 1
fi
echo "PASS: docs/places.md's settings table is recog settings --markdown's"

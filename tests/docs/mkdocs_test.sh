#!/usr/bin/env bash
# The user guide (docs/, mkdocs.yml) builds with `mkdocs build --strict` without a single warning,
# every intra-site link that names an anchor (page.md#anchor, #anchor) finds it (MkDocs 1.4 checks
# pages, not anchors), and README.md stays a front door: at most 250 lines, with the section
# "## The two commands". Usage: mkdocs_test.sh PROJECT_DIR. Exit 77 (skipped) without mkdocs.
set -u

project_dir=$(cd "${1:?usage: mkdocs_test.sh PROJECT_DIR}" && pwd) || exit 1
max_readme_lines=250

if ! command -v mkdocs >/dev/null 2>&1; then
  echo "SKIP: mkdocs not found"
  exit 77
fi

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
failures=0
fail() { echo "FAIL: $*"; failures=$((failures + 1)); }

cd "$project_dir" || { echo "FAIL: no project directory '$project_dir'"; exit 1; }

# 1. The site builds, strict, and prints no warning.
if ! mkdocs build --strict -f mkdocs.yml --site-dir "$tmp/site" >"$tmp/mkdocs.log" 2>&1; then
  cat "$tmp/mkdocs.log"
  fail "mkdocs build --strict failed"
elif grep -q 'WARNING' "$tmp/mkdocs.log"; then
  cat "$tmp/mkdocs.log"
  fail "mkdocs build printed warnings"
else
  echo "ok: mkdocs build --strict, no warning"
fi

# 2. Every anchor of an intra-site link exists in the page built from it.
if [ -d "$tmp/site" ]; then
  if python3 - "$project_dir/docs" "$tmp/site" >"$tmp/anchors.log" 2>&1 <<'PY'
import html.parser, pathlib, re, sys
docs, site = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])

class Ids(html.parser.HTMLParser):
    def __init__(self):
        super().__init__()
        self.ids = set()
    def handle_starttag(self, tag, attrs):
        for k, v in attrs:
            if k == 'id' and v:
                self.ids.add(v)

def ids_of(md):
    rel = md.relative_to(docs).with_suffix('')
    page = site / ('index.html' if rel.name == 'index' else rel / 'index.html')
    if not page.exists():
        page = site / rel.with_suffix('.html')
    p = Ids()
    p.feed(page.read_text(encoding='utf-8'))
    return p.ids

bad = 0
for md in sorted(docs.rglob('*.md')):
    text = re.sub(r'```.*?```', '', md.read_text(encoding='utf-8'), flags=re.S)
    for target, anchor in re.findall(r'\]\(([^)\s#]*\.md)?#([^)\s]+)\)', text):
        dest = (md.parent / target).resolve() if target else md
        if not dest.exists():
            print(f'{md.relative_to(docs)}: link to a missing page {target}')
            bad += 1
        elif anchor not in ids_of(dest):
            print(f'{md.relative_to(docs)}: no anchor #{anchor} in {target or md.name}')
            bad += 1
sys.exit(1 if bad else 0)
PY
  then
    echo "ok: every intra-site anchor exists"
  else
    cat "$tmp/anchors.log"
    fail "links to missing anchors"
  fi
fi

# 3. README.md: short, and still holding the two commands.
lines=$(wc -l <README.md)
if [ "$lines" -le "$max_readme_lines" ]; then
  echo "ok: README.md has $lines lines (at most $max_readme_lines)"
else
  fail "README.md has $lines lines, more than $max_readme_lines"
fi
if grep -qx '## The two commands' README.md; then
  echo "ok: README.md has the section '## The two commands'"
else
  fail "README.md lost the section '## The two commands'"
fi

if [ "$failures" -ne 0 ]; then
  echo "$failures check(s) failed"
  exit 1
fi
echo "PASS"

#!/usr/bin/env bash
# Fails when a C++ file differs from the project's .clang-format style.
# Fix with: clang-format -i $(git ls-files '*.h' '*.cc')
set -euo pipefail
cd "$(dirname "$0")/.."
mapfile -t files < <(git ls-files '*.h' '*.cc')
if [ ${#files[@]} -eq 0 ]; then
  echo "check_format: no C++ files"
  exit 0
fi
clang-format --dry-run --Werror "${files[@]}"
echo "check_format: ${#files[@]} files formatted"

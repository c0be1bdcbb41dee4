#!/usr/bin/env bash
# The README's first command on a fresh virtual environment, then every demo's --test: what
# a newcomer gets from the base install (issue 58). Not part of the suite (it installs from
# PyPI, minutes); test_demos runs the demos with every extra made unimportable instead.
#   tools/fresh_venv_demos.sh [VENV_DIR]      (default: a temporary folder, removed after)
set -euo pipefail
cd "$(dirname "$0")/.."
venv=${1:-$(mktemp -d)/venv}
python3 -m venv "$venv"
"$venv/bin/pip" install -q .
out=$(mktemp -d)
failed=0
for demo in demos/*.py; do
    name=$(basename "$demo" .py)
    if "$venv/bin/python" "$demo" --test --no-progress --out-dir "$out/$name" >"$out/$name.log" 2>&1; then
        echo "ok      $name"
    else
        echo "FAILED  $name (log: $out/$name.log)"; failed=1
    fi
done
exit $failed

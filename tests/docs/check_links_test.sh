#!/usr/bin/env bash
# The link check itself: it names a broken link and fails, ignores links in code and web links,
# and passes once the target exists.
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
mkdir -p "$dir/docs"
cat > "$dir/README.md" <<'MD'
# A project
See [the guide](docs/guide.md#start), [the web](https://example.org/x.md) and `[code](none.md)`.
![a plot](docs/plot.png)
MD
echo "# Guide" > "$dir/docs/guide.md"
fail() { echo "check_links_test: $*" >&2; exit 1; }

if output=$(bash "$here/check_links.sh" "$dir" 2>&1); then
  fail "a missing docs/plot.png passed: $output"
fi
grep -q "README.md:3: docs/plot.png" <<< "$output" || fail "the broken link is not named: $output"
grep -q "example.org\|none.md\|guide.md" <<< "$output" && fail "a good, web or code link was reported: $output"
touch "$dir/docs/plot.png"
bash "$here/check_links.sh" "$dir" > /dev/null || fail "every link resolves, yet the check failed"
echo "check_links_test: ok"

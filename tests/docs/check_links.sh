#!/usr/bin/env bash
# Checks that every relative link of the project's Markdown files points at a file or folder
# that exists: [text](path), [text](path#anchor), ![alt](path), reference definitions
# ([label]: path) and the src/href of inline HTML (<img src="...">). Links are resolved against
# the folder of the Markdown file that holds them (a target starting with / against the
# repository root); an #anchor is stripped before the check, and http(s):, mailto: and pure
# #anchor links are not checked. Links inside fenced code blocks and `code spans` are not links.
#
# Files: every *.md of the repository that git tracks or would track (README.md, docs/**/*.md,
# ...; not ignored ones) except those under build/ and runs/; without git, every *.md found
# under the root outside those folders.
#
#   bash tests/docs/check_links.sh [REPO_ROOT]     # default: this script's ../..
#
# Prints each broken link as `file:line: target` and exits 1, else prints one summary line and
# exits 0.
set -euo pipefail

root=${1:-$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)}
if [ ! -d "$root" ]; then
  echo "check_links: no such folder: $root" >&2
  exit 2
fi
root=$(cd "$root" && pwd)
cd "$root"

files=()
if git -C "$root" rev-parse --is-inside-work-tree >/dev/null 2>&1; then
  while IFS= read -r f; do
    files+=("$f")
  done < <(git -C "$root" ls-files --cached --others --exclude-standard -- '*.md' |
           grep -Ev '^(build|runs)/' | sort -u || true)
else
  while IFS= read -r f; do
    files+=("${f#./}")
  done < <(find . \( -path ./build -o -path ./runs -o -path ./.git \) -prune -o \
                -type f -name '*.md' -print | sort)
fi

# Prints "line<TAB>target" for every link of a Markdown file on stdin.
extract_links() {
  awk '
    /^[ \t]*(```|~~~)/ { fence = !fence; next }
    fence { next }
    {
      line = $0
      gsub(/`[^`]*`/, "", line)                       # code spans hold no links
      if (match(line, /^ ? ? ?\[[^]]+\]:[ \t]+[^ \t]+/)) {  # [label]: target
        def = substr(line, RSTART, RLENGTH)
        sub(/^ ? ? ?\[[^]]+\]:[ \t]+/, "", def)
        print NR "\t" def
        next
      }
      rest = line
      while (match(rest, /\]\([^)]*\)/)) {             # [text](target) and ![alt](target)
        t = substr(rest, RSTART + 2, RLENGTH - 3)
        rest = substr(rest, RSTART + RLENGTH)
        print NR "\t" t
      }
      rest = line
      while (match(rest, /<[A-Za-z][^>]*(src|href)="[^"]*"/)) {   # <img src="..."> <a href="...">
        tag = substr(rest, RSTART, RLENGTH)
        rest = substr(rest, RSTART + RLENGTH)
        sub(/^.*(src|href)="/, "", tag)
        sub(/"$/, "", tag)
        print NR "\t" tag
      }
    }'
}

checked=0
broken=0
for f in "${files[@]}"; do
  [ -f "$f" ] || continue
  dir=$(dirname "$f")
  while IFS=$'\t' read -r line target; do
    # [text](<path with spaces> "title"): drop the angle brackets and a title.
    target=${target#"${target%%[![:space:]]*}"}
    if [[ $target == \<*\>* ]]; then
      target=${target#<}
      target=${target%%>*}
    else
      target=${target%%[[:space:]]*}
    fi
    case $target in
      '' | '#'* | http://* | https://* | mailto:*) continue ;;
    esac
    path=${target%%#*}
    path=${path%%\?*}
    path=${path//%20/ }
    [ -n "$path" ] || continue
    checked=$((checked + 1))
    if [[ $path == /* ]]; then
      resolved=$root$path
    else
      resolved=$dir/$path
    fi
    if [ ! -e "$resolved" ]; then
      echo "$f:$line: $target"
      broken=$((broken + 1))
    fi
  done < <(extract_links < "$f")
done

if [ "$broken" -gt 0 ]; then
  echo "check_links: $broken broken of $checked relative links in ${#files[@]} Markdown files" >&2
  exit 1
fi
echo "check_links: all $checked relative links resolve in ${#files[@]} Markdown files"

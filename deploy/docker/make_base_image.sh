#!/bin/bash
# Makes the Debian 12 base image that deploy/docker/Dockerfile starts FROM, without an image
# registry: mmdebstrap builds a minimal bookworm system from the Debian mirrors this host's apt
# uses, and podman (or docker) imports it under the Dockerfile's name.
#
#   bash deploy/docker/make_base_image.sh [--force] [--name NAME] [--print-sources]
#
# The image keeps the host's Debian sources (so apt-get in the Dockerfile reaches the same
# mirror) and the host's Acquire::Check-Valid-Until / Check-Date settings (a mirror frozen at a
# snapshot date has expired Release files otherwise). Third-party apt sources are left out.
set -euo pipefail

name=debian:12
force=0
print_sources=0
usage() {
  cat <<'EOF'
Usage: make_base_image.sh [--force] [--name NAME] [--print-sources]

Builds a minimal Debian 12 (bookworm) root file system with mmdebstrap from the Debian mirrors
in /etc/apt/sources.list and /etc/apt/sources.list.d/*.{list,sources}, and imports it as the
image NAME (default debian:12, the name deploy/docker/Dockerfile uses) with podman, or docker
when podman is absent. Does nothing when the image exists, unless --force. --print-sources
prints the apt sources it would use and exits.

Needs: mmdebstrap (apt-get install mmdebstrap) and podman or docker (apt-get install podman
runc). Runs as root (mmdebstrap's root mode).

Environment: INDRIVE_CONTAINER_ENGINE=podman|docker chooses the engine.
EOF
}
while [ $# -gt 0 ]; do
  case "$1" in
    --force) force=1 ;;
    --name) name=$2; shift ;;
    --print-sources) print_sources=1 ;;
    -h|--help) usage; exit 0 ;;
    *) echo "make_base_image.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
  shift
done

die() { echo "make_base_image.sh: $*" >&2; exit 1; }

# The host's Debian bookworm sources, as one-line entries. Only suites of bookworm itself
# (bookworm, bookworm-updates, bookworm-security, bookworm-backports) are kept, which leaves
# out third-party repositories (their suites have other names).
debian_sources() {
  local f
  {
    for f in /etc/apt/sources.list /etc/apt/sources.list.d/*.list; do
      [ -f "$f" ] || continue
      sed -e 's/#.*//' "$f" | awk '$1 == "deb" {
        i = 2; if ($2 ~ /^\[/) { while ($i !~ /\]$/) i++; i++ }
        uri = $i; suite = $(i + 1); comps = ""
        for (j = i + 2; j <= NF; j++) comps = comps " " $j
        print uri, suite, comps }'
    done
    for f in /etc/apt/sources.list.d/*.sources; do
      [ -f "$f" ] || continue
      # deb822 stanzas: blank lines separate them; Enabled: no skips one.
      # Comment lines are dropped, not blanked: a blank line ends a stanza.
      sed -e '/^[[:space:]]*#/d' "$f" | awk '
        function flush() {
          if (types ~ /(^| )deb( |$)/ && enabled != "no")
            for (u = 1; u <= nu; u++) for (s = 1; s <= ns; s++) print uris[u], suites[s], comps
          types = ""; enabled = ""; nu = 0; ns = 0; comps = ""
        }
        /^[ \t]*$/ { flush(); next }
        {
          key = tolower($1); sub(/:$/, "", key); $1 = ""; sub(/^ +/, "")
          if (key == "types") types = $0
          else if (key == "uris") nu = split($0, uris, " ")
          else if (key == "suites") ns = split($0, suites, " ")
          else if (key == "components") comps = " " $0
          else if (key == "enabled") enabled = tolower($0)
        }
        END { flush() }'
    done
  } | awk '$2 ~ /^bookworm(-updates|-security|-backports)?$/ { $1 = $1; print "deb " $0 }' | sort -u
}
mapfile -t sources < <(debian_sources)
if [ ${#sources[@]} -eq 0 ]; then
  sources=("deb http://deb.debian.org/debian bookworm main"
           "deb http://deb.debian.org/debian bookworm-updates main"
           "deb http://deb.debian.org/debian-security bookworm-security main")
  echo "make_base_image.sh: no Debian bookworm source in /etc/apt; using deb.debian.org" >&2
fi
if [ "$print_sources" = 1 ]; then printf '%s\n' "${sources[@]}"; exit 0; fi

engine=${INDRIVE_CONTAINER_ENGINE:-}
if [ -z "$engine" ]; then
  if command -v podman >/dev/null; then engine=podman
  elif command -v docker >/dev/null; then engine=docker
  else die "neither podman nor docker is installed: apt-get install podman runc (or docker.io)"
  fi
fi
command -v "$engine" >/dev/null || die "$engine is not installed"
"$engine" info >/dev/null 2>&1 \
  || die "'$engine info' fails: is its service running (docker) or its set-up complete?"

# podman's short names: "debian:12" is looked up as localhost/debian:12 first for local images,
# but a registry pull is tried when the name is missing locally. Tag both spellings so that
# FROM debian:12 resolves to the local image and never reaches for a registry.
if [ "$engine" = podman ]; then
  case "$name" in
    */*) full_names=("$name") ;;
    *:*) full_names=("localhost/$name" "docker.io/library/$name") ;;
    *) full_names=("localhost/$name:latest" "docker.io/library/$name:latest") ;;
  esac
else
  full_names=("$name")
fi

exists() { "$engine" image inspect "$1" >/dev/null 2>&1; }
if [ "$force" = 0 ]; then
  all=1
  for n in "${full_names[@]}"; do exists "$n" || all=0; done
  if [ "$all" = 1 ]; then
    echo "make_base_image.sh: image $name exists ($engine); --force rebuilds it"
    exit 0
  fi
fi

command -v mmdebstrap >/dev/null \
  || die "mmdebstrap is not installed: apt-get install mmdebstrap"
[ "$(id -u)" = 0 ] || die "run as root (mmdebstrap builds the root file system in root mode)"
printf 'make_base_image.sh: source %s\n' "${sources[@]}"


# Apt options of the host that a frozen mirror needs, carried into the image.
aptopts=()
for opt in Acquire::Check-Valid-Until Acquire::Check-Date; do
  value=$(apt-config shell v "$opt" 2>/dev/null | sed -n "s/^v='\(.*\)'$/\1/p")
  [ -n "$value" ] && aptopts+=("--aptopt=$opt \"$value\";")
done

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
start=$(date +%s)
mmdebstrap --mode=root --variant=minbase --include=ca-certificates \
  "${aptopts[@]}" bookworm "$work/rootfs.tar" "${sources[@]}"

"$engine" import --change 'CMD ["/bin/bash"]' --change 'ENV LANG=C.UTF-8' \
  "$work/rootfs.tar" "${full_names[0]}" >/dev/null
for n in "${full_names[@]:1}"; do "$engine" tag "${full_names[0]}" "$n"; done
echo "make_base_image.sh: imported $name ($engine, ${full_names[*]}) in $(($(date +%s) - start)) s"

#!/bin/sh
# Entrypoint of the InDRiVE image: picks the DDS profile, then runs the command.
#
#   INDRIVE_DISCOVERY_SERVER=host:port  every participant is a client of that discovery server
#                                       (deploy/dds/discovery_server.xml; the programs read the
#                                       address from this variable);
#   INDRIVE_DISCOVERY_SERVER empty      UDP with multicast discovery (deploy/dds/default.xml).
# Shared memory (single_host.xml) is never used: it does not cross containers.
#
#   entrypoint.sh discovery-server      runs the discovery server itself on this container's
#                                       address and the port of INDRIVE_DISCOVERY_SERVER.
set -eu

data=${INDRIVE_DATA_DIR:-$(cd "$(dirname "$0")/../.." && pwd)}
server=${INDRIVE_DISCOVERY_SERVER:-}
host=${server%:*}
port=11811
case "$server" in *:*) port=${server##*:} ;; esac

# Resolves a host name to an IPv4 address, waiting for the network's DNS (up to 60 s).
resolve() {
  tries=0
  while :; do
    address=$(getent ahostsv4 "$1" 2>/dev/null | awk 'NR == 1 { print $1 }')
    if [ -n "$address" ]; then
      echo "$address"
      return 0
    fi
    tries=$((tries + 1))
    if [ "$tries" -ge 60 ]; then
      echo "entrypoint: cannot resolve discovery server '$1'; start it or set" \
           "INDRIVE_DISCOVERY_SERVER=host:port (empty for multicast discovery)" >&2
      return 1
    fi
    sleep 1
  done
}

if [ "${1:-}" = "discovery-server" ]; then
  own=$(resolve "$(cat /etc/hostname)")
  echo "entrypoint: discovery server on $own:$port"
  # Not exec'd: `fastdds` dies of SIGTERM (exit 143) when compose stops it; a stop asked for is
  # a clean end (0), while a server that fails on its own still gives its own exit code.
  # `fastdds discovery` is a Python wrapper that starts fast-discovery-server and does not pass a
  # stop on to it (the server outlived it, holding its port): run the server itself where it is.
  if command -v fast-discovery-server >/dev/null 2>&1; then
    fast-discovery-server -i 0 -l "$own" -p "$port" &
  else
    fastdds discovery -i 0 -l "$own" -p "$port" &
  fi
  server_pid=$!
  trap 'kill -TERM "$server_pid" 2>/dev/null; wait "$server_pid" || true; exit 0' TERM INT
  status=0
  wait "$server_pid" || status=$?
  exit "$status"
fi

if [ -n "$server" ]; then
  # The programs read INDRIVE_DISCOVERY_SERVER themselves (and resolve the name); waiting here
  # only lets a container that starts before the discovery server's name exists wait for it.
  resolve "$host" >/dev/null
  profile="$data/deploy/dds/discovery_server.xml"
  echo "entrypoint: DDS through the discovery server $server" >&2
else
  profile="$data/deploy/dds/default.xml"
  echo "entrypoint: DDS over UDP with multicast discovery" >&2
fi
export FASTRTPS_DEFAULT_PROFILES_FILE="$profile"
exec "$@"

#!/usr/bin/env bash
# Makes the DDS Security folder of one run: a certificate authority, one identity per role, the
# signed governance document and one signed permissions document per role.
#
#   deploy/dds/make_security.sh OUT_DIR [--days N] [--domain ID|any] [--force]
#
#   --days N      validity of the CA and of every certificate and permission (default 365)
#   --domain ID   the only DDS domain the documents allow (0..232); `any` (default) allows all
#   --force       replace the files of an existing, non-empty OUT_DIR
#
# Every process then runs with `--dds-security OUT_DIR` and picks its own role's files
# (deploy/dds/README.md, "DDS Security"). ca.key signs everything: keep it on this host.
#
# Roles and what their permissions allow (topics of common/dds/include/indrive/dds/messages.h):
#   learner    publishes policy, policy_announce, allowance, heartbeat;
#              subscribes trajectory, episode_result, snapshot_request, heartbeat
#   actor      publishes trajectory, episode_result, heartbeat, snapshot_request;
#              subscribes policy, policy_announce, allowance, heartbeat
#   evaluator  publishes episode_result, snapshot_request, heartbeat;
#              subscribes policy, policy_announce, heartbeat
#   observer   subscribes every indrive/* topic and publishes nothing (monitors, dashboards)
# Anything else is denied.
set -euo pipefail

usage() {
  sed -n '2,10p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//' >&2
  exit 2
}
die() {
  echo "make_security.sh: $*" >&2
  exit 1
}

out_dir=""
days=365
domain=any
force=0
while (($# > 0)); do
  case $1 in
    --days)
      (($# >= 2)) || die "--days needs a number of days"
      days=$2
      shift 2
      ;;
    --domain)
      (($# >= 2)) || die "--domain needs a domain id (0..232) or 'any'"
      domain=$2
      shift 2
      ;;
    --force)
      force=1
      shift
      ;;
    -h | --help) usage ;;
    -*) die "unknown option '$1' (see --help)" ;;
    *)
      [[ -z $out_dir ]] || die "one output folder only; '$out_dir' and '$1' were given"
      out_dir=$1
      shift
      ;;
  esac
done
[[ -n $out_dir ]] || usage
[[ $days =~ ^[1-9][0-9]*$ ]] || die "--days must be a positive whole number, not '$days'"
if [[ $domain != any ]]; then
  if [[ ! $domain =~ ^[0-9]+$ ]] || ((10#$domain > 232)); then
    die "--domain must be a DDS domain id 0..232 or 'any', not '$domain'"
  fi
  domain=$((10#$domain))
fi
command -v openssl > /dev/null || die "openssl is not installed (apt-get install openssl)"
if [[ -d $out_dir && -n $(ls -A "$out_dir") && $force -eq 0 ]]; then
  die "'$out_dir' exists and is not empty; it may hold another run's CA. Pick a new folder or" \
    "pass --force to replace its files"
fi
[[ ! -e $out_dir || -d $out_dir ]] || die "'$out_dir' exists and is not a folder"

roles=(learner actor evaluator observer)
# Topics each role may publish and subscribe (the shipped roles; keep in step with the header).
declare -A publishes=(
  [learner]="indrive/policy indrive/policy_announce indrive/allowance indrive/heartbeat"
  [actor]="indrive/trajectory indrive/episode_result indrive/heartbeat indrive/snapshot_request"
  [evaluator]="indrive/episode_result indrive/snapshot_request indrive/heartbeat"
  [observer]=""
)
declare -A subscribes=(
  [learner]="indrive/trajectory indrive/episode_result indrive/snapshot_request indrive/heartbeat"
  [actor]="indrive/policy indrive/policy_announce indrive/allowance indrive/heartbeat"
  [evaluator]="indrive/policy indrive/policy_announce indrive/heartbeat"
  [observer]="indrive/*"
)

# Everything is made in a scratch folder first and moved into OUT_DIR at the end, so a failure
# half-way never leaves a folder whose files do not belong together.
umask 077
work=$(mktemp -d "${TMPDIR:-/tmp}/indrive-security.XXXXXX")
trap 'rm -rf "$work"' EXIT

# The certificates start a day in the past: hosts whose clocks lag a little still accept them,
# and Fast DDS reads the permissions' dates as local time, which may be hours behind UTC.
start=$(date -u -d '-1 day' +%Y%m%d%H%M%SZ)
end=$(date -u -d "+$days days" +%Y%m%d%H%M%SZ)

cat > "$work/openssl.cnf" << EOF
[ ca ]
default_ca = run_ca

[ run_ca ]
dir = $work
database = \$dir/index.txt
new_certs_dir = \$dir/issued
serial = \$dir/serial
default_md = sha256
policy = any_name
unique_subject = no
copy_extensions = none
email_in_dn = no

[ any_name ]
organizationName = supplied
organizationalUnitName = optional
commonName = supplied

[ req ]
distinguished_name = req_name
prompt = no

[ req_name ]

[ ca_extensions ]
basicConstraints = critical, CA:true
keyUsage = critical, keyCertSign, cRLSign, digitalSignature
subjectKeyIdentifier = hash

[ identity_extensions ]
basicConstraints = critical, CA:false
keyUsage = critical, digitalSignature, keyAgreement
subjectKeyIdentifier = hash
authorityKeyIdentifier = keyid
EOF
: > "$work/index.txt"
mkdir "$work/issued"
openssl rand -hex 16 > "$work/serial"

run_openssl() {
  local output
  if ! output=$(openssl "$@" 2>&1); then
    echo "$output" >&2
    die "openssl $1 failed (above)"
  fi
}

# An EC prime256v1 key: the curve the builtin PKI-DH plugin signs its handshakes with.
new_key() { run_openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:prime256v1 -out "$1"; }

# Signs the request $1 into the certificate $2 with the extensions section $3 (extra options
# after that, e.g. -selfsign).
issue() {
  local request=$1 certificate=$2 extensions=$3
  shift 3
  run_openssl ca -batch -notext -config "$work/openssl.cnf" -keyfile "$work/ca.key" \
    -cert "$work/ca.pem" -startdate "$start" -enddate "$end" -extensions "$extensions" \
    -in "$request" -out "$certificate" "$@"
}

# The CA: self-signed, so its dates are set like every other certificate's.
new_key "$work/ca.key"
run_openssl req -new -config "$work/openssl.cnf" -key "$work/ca.key" \
  -subj "/O=InDRiVE/OU=DDS Security/CN=InDRiVE run CA" -out "$work/ca.csr"
issue "$work/ca.csr" "$work/ca.pem" ca_extensions -selfsign

for role in "${roles[@]}"; do
  new_key "$work/$role.key"
  run_openssl req -new -config "$work/openssl.cnf" -key "$work/$role.key" \
    -subj "/O=InDRiVE/OU=DDS Security/CN=$role" -out "$work/$role.csr"
  issue "$work/$role.csr" "$work/$role.pem" identity_extensions
done

if [[ $domain == any ]]; then
  domains_xml="<id_range><min>0</min><max>232</max></id_range>"
else
  domains_xml="<id>$domain</id>"
fi

cat > "$work/governance.xml" << EOF
<?xml version="1.0" encoding="UTF-8"?>
<!-- Governance of one InDRiVE run (made by deploy/dds/make_security.sh): only participants with
     a certificate of this run's CA join; discovery, liveliness and every topic's submessages and
     payloads are encrypted. The RTPS message as a whole is not encrypted a second time
     (rtps_protection_kind NONE): Fast DDS 2.9 with statistics aborts when that outer encryption
     grows a full message past its buffer (an assertion in add_statistics_submessage; 2 of 3
     transfers across two hosts crashed so), and what it would add is the message header. -->
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-Security/20170801/omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      <domains>$domains_xml</domains>
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>ENCRYPT</discovery_protection_kind>
      <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>
      <rtps_protection_kind>NONE</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>indrive/*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>ENCRYPT</metadata_protection_kind>
          <data_protection_kind>ENCRYPT</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
EOF

# "notBefore=Dec  1 07:00:00 2026 GMT" -> "2026-12-01T07:00:00", the form the permissions take.
permission_date() {
  local line
  line=$(openssl x509 -in "$1" -noout "-$2")
  date -u -d "${line#*=}" +%Y-%m-%dT%H:%M:%S
}

topics_xml() {
  local topic
  for topic in $1; do
    printf '            <topic>%s</topic>\n' "$topic"
  done
}

for role in "${roles[@]}"; do
  # The subject exactly as the access-control plugin compares it (RFC 2253, most specific
  # first).
  subject=$(openssl x509 -in "$work/$role.pem" -noout -subject -nameopt RFC2253)
  subject=${subject#subject=}
  {
    cat << EOF
<?xml version="1.0" encoding="UTF-8"?>
<!-- Permissions of the $role role of one InDRiVE run (made by deploy/dds/make_security.sh). -->
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-Security/20170801/omg_shared_ca_permissions.xsd">
  <permissions>
    <grant name="indrive_$role">
      <subject_name>$subject</subject_name>
      <validity>
        <not_before>$(permission_date "$work/$role.pem" startdate)</not_before>
        <not_after>$(permission_date "$work/$role.pem" enddate)</not_after>
      </validity>
      <allow_rule>
        <domains>$domains_xml</domains>
EOF
    if [[ -n ${publishes[$role]} ]]; then
      printf '        <publish>\n          <topics>\n'
      topics_xml "${publishes[$role]}"
      printf '          </topics>\n        </publish>\n'
    fi
    printf '        <subscribe>\n          <topics>\n'
    topics_xml "${subscribes[$role]}"
    printf '          </topics>\n        </subscribe>\n'
    cat << EOF
      </allow_rule>
      <default>DENY</default>
    </grant>
  </permissions>
</dds>
EOF
  } > "$work/permissions-$role.xml"
done

# S/MIME signatures by the CA, which is both identity CA and permissions CA of the run.
for document in governance "${roles[@]/#/permissions-}"; do
  run_openssl smime -sign -text -md sha256 -in "$work/$document.xml" -signer "$work/ca.pem" \
    -inkey "$work/ca.key" -out "$work/$document.p7s"
  run_openssl smime -verify -in "$work/$document.p7s" -CAfile "$work/ca.pem" -out /dev/null
done
for role in "${roles[@]}"; do
  run_openssl verify -CAfile "$work/ca.pem" "$work/$role.pem"
done

made=(ca.pem ca.key governance.xml governance.p7s)
for role in "${roles[@]}"; do
  made+=("$role.pem" "$role.key" "permissions-$role.xml" "permissions-$role.p7s")
done
mkdir -p "$out_dir"
for file in "${made[@]}"; do
  case $file in
    *.key) chmod 600 "$work/$file" ;;
    *) chmod 644 "$work/$file" ;;
  esac
  mv -f "$work/$file" "$out_dir/$file"
done

out_abs=$(cd "$out_dir" && pwd)
echo "DDS Security folder $out_abs (valid until $(date -u -d "${end:0:8}" +%Y-%m-%d)," \
  "domain $domain):"
echo "  CA          ca.pem, ca.key (ca.key never leaves this host)"
echo "  governance  governance.p7s (authenticated participants only; discovery, liveliness and every topic encrypted)"
for role in "${roles[@]}"; do
  printf '  %-10s  %s.pem, %s.key, permissions-%s.p7s\n' "$role" "$role" "$role" "$role"
done
echo "Use: pass --dds-security $out_abs to every process; another host needs ca.pem," \
  "governance.p7s and its role's <role>.pem, <role>.key, permissions-<role>.p7s"

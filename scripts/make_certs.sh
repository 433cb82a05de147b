#!/usr/bin/env bash
# Makes what a TLS + token fusiond needs (docs/security.md), in a folder of its own:
#   ca.pem / ca.key          a private CA (10 years), the trust root of servers and clients
#   server.pem / server.key  fusiond's certificate: DNS fusiond and localhost, IP 127.0.0.1
#                            (more names: FUSION_CERT_NAMES="DNS:map.example,IP:10.0.0.5")
#   client.pem / client.key  a client certificate for mutual TLS
#   tokens                   one admin and one read token ("<role> <token>" lines)
#   admin.token / read.token each token alone, for --token-file
# Usage: scripts/make_certs.sh DIR   (refuses to overwrite an existing CA in DIR)
set -euo pipefail

usage() { sed -n '2,9p' "$0" | sed 's/^# \{0,1\}//'; }
if [ $# -eq 1 ] && { [ "$1" = "--help" ] || [ "$1" = "-h" ]; }; then usage; exit 0; fi
if [ $# -ne 1 ] || [ "${1#-}" != "$1" ]; then usage >&2; exit 2; fi
dir=$1
command -v openssl > /dev/null || { echo "make_certs.sh: needs openssl (apt-get install openssl)" >&2; exit 1; }
mkdir -p "$dir"
if [ -e "$dir/ca.key" ]; then
  echo "make_certs.sh: $dir/ca.key exists; remove the folder's files to make new ones" >&2
  exit 1
fi
umask 077
names="DNS:fusiond,DNS:localhost,IP:127.0.0.1${FUSION_CERT_NAMES:+,$FUSION_CERT_NAMES}"
quiet() { "$@" > /dev/null 2>&1 || { echo "make_certs.sh: failed: $*" >&2; exit 1; }; }

quiet openssl req -x509 -newkey rsa:2048 -nodes -days 3650 -subj "/CN=fusion private CA" \
  -keyout "$dir/ca.key" -out "$dir/ca.pem" \
  -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,keyCertSign,cRLSign"
sign() {  # sign NAME CN EXTENSIONS
  quiet openssl req -newkey rsa:2048 -nodes -subj "/CN=$2" -keyout "$dir/$1.key" -out "$dir/$1.csr"
  printf '%s\n' "$3" > "$dir/$1.ext"
  quiet openssl x509 -req -in "$dir/$1.csr" -CA "$dir/ca.pem" -CAkey "$dir/ca.key" \
    -CAcreateserial -days 825 -out "$dir/$1.pem" -extfile "$dir/$1.ext"
  rm -f "$dir/$1.csr" "$dir/$1.ext"
}
sign server fusiond "subjectAltName=$names
extendedKeyUsage=serverAuth"
sign client fusion-client "extendedKeyUsage=clientAuth"
rm -f "$dir/ca.srl"

admin=$(openssl rand -hex 24)
read_token=$(openssl rand -hex 24)
printf '# fusiond bearer tokens: <role> <token>\nadmin %s\nread %s\n' "$admin" "$read_token" > "$dir/tokens"
printf '%s\n' "$admin" > "$dir/admin.token"
printf '%s\n' "$read_token" > "$dir/read.token"
chmod 644 "$dir/ca.pem" "$dir/server.pem" "$dir/client.pem"
echo "made in $dir: ca.pem, server.pem/.key ($names), client.pem/.key, tokens, admin.token, read.token"

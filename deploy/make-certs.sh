#!/usr/bin/env bash
# Makes what a TLS cluster needs (docs/security.md) in DIR:
#
#   ca.crt ca.key             the cluster's certificate authority (keep ca.key
#                             offline once the certificates are made)
#   root.crt root.key         a certificate per role, signed by the CA; its
#   worker.crt worker.key     common name and DNS name are the role
#   display.crt display.key   ("transtick-worker"), which is what peers check
#   tokens                    the root's clients: "admin TOKEN admin" and
#                             "client TOKEN" (--tokens)
#   admin.token client.token  each client's token alone (--token-file)
#
# Usage: deploy/make-certs.sh DIR [--uid UID] [--days N] [--force]
#   --uid UID   owner of the daemons' keys and of tokens (the image runs as
#               10001); admin.token and client.token stay the caller's
#   --days N    validity of the role certificates (default 825)
#   --force     replace what DIR holds; without it, existing files are kept
#               and only missing ones are made (a new role certificate is
#               signed by the CA already there)
set -euo pipefail

dir="" uid="" days=825 force=0
while (($#)); do
  case $1 in
    --uid) uid=$2; shift 2 ;;
    --days) days=$2; shift 2 ;;
    --force) force=1; shift ;;
    -h | --help) sed -n '2,19p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    -*) echo "make-certs: unknown option $1" >&2; exit 2 ;;
    *) [[ -z $dir ]] || { echo "make-certs: one DIR only" >&2; exit 2; }; dir=$1; shift ;;
  esac
done
[[ -n $dir ]] || { echo "usage: deploy/make-certs.sh DIR [--uid UID] [--days N] [--force]" >&2; exit 2; }
command -v openssl >/dev/null || { echo "make-certs: needs openssl (apt-get install openssl)" >&2; exit 1; }

mkdir -p "$dir"
cd "$dir"
umask 077
if ((force)); then rm -f ca.crt ca.key ca.srl {root,worker,display}.{crt,key} tokens {admin,client}.token; fi

if [[ ! -s ca.key || ! -s ca.crt ]]; then
  openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out ca.key 2>/dev/null
  openssl req -x509 -new -key ca.key -sha256 -days 3650 -subj "/CN=transtick cluster CA" \
    -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,keyCertSign,cRLSign" \
    -out ca.crt 2>/dev/null
  rm -f {root,worker,display}.crt  # signed by another CA, if any
fi

for role in root worker display; do
  [[ -s $role.key && -s $role.crt ]] && continue
  openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$role.key" 2>/dev/null
  openssl req -new -key "$role.key" -subj "/CN=transtick-$role" -out "$role.csr" 2>/dev/null
  printf '%s\n' "subjectAltName=DNS:transtick-$role" "basicConstraints=critical,CA:FALSE" \
    "keyUsage=critical,digitalSignature" "extendedKeyUsage=serverAuth,clientAuth" >"$role.ext"
  openssl x509 -req -in "$role.csr" -CA ca.crt -CAkey ca.key -CAcreateserial -days "$days" \
    -sha256 -extfile "$role.ext" -out "$role.crt" 2>/dev/null
  rm -f "$role.csr" "$role.ext"
done

token() { head -c 24 /dev/urandom | base64 | tr -d '/+=\n'; }
if [[ ! -s tokens ]]; then
  admin=$(token) client=$(token)
  printf '# NAME TOKEN [admin]: the root'"'"'s clients (transtick-root --tokens)\nadmin %s admin\nclient %s\n' \
    "$admin" "$client" >tokens
  printf '%s\n' "$admin" >admin.token
  printf '%s\n' "$client" >client.token
fi

chmod 644 ca.crt root.crt worker.crt display.crt
chmod 600 ca.key root.key worker.key display.key tokens admin.token client.token
# The daemons' files go to the image's user; the client tokens stay the caller's.
if [[ -n $uid ]]; then chown "$uid" root.key worker.key display.key tokens; fi
echo "make-certs: $(pwd): CA, root/worker/display certificates and tokens ready" >&2

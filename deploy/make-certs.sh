#!/usr/bin/env bash
# Makes what a TLS cluster needs (docs/security.md) in DIR:
#
#   ca.crt ca.key             the cluster's certificate authority (keep ca.key
#                             offline once the certificates are made)
#   root.crt root.key         a certificate per role, signed by the CA; its
#   worker.crt worker.key     common name and DNS name are the role
#   display.crt display.key   ("transtick-worker"), which is what peers check
#   web.crt web.key           the web gateway's HTTPS certificate, for browsers:
#                             localhost, 127.0.0.1, transtick-web and each
#                             --web-host name (or bring a certificate of
#                             your own for the public name)
#   tokens                    the root's clients: "admin TOKEN admin" and
#                             "client TOKEN" (--tokens)
#   admin.token client.token  each client's token alone (--token-file)
#
# Usage: deploy/make-certs.sh DIR [--uid UID] [--days N] [--web-host NAME]... [--force]
#   --uid UID   owner of the daemons' keys and of tokens (the image runs as
#               10001); admin.token and client.token stay the caller's
#   --days N    validity of the role certificates (default 825)
#   --web-host NAME  a name (or IP address) browsers reach the gateway by
#   --force     replace what DIR holds; without it, existing files are kept
#               and only missing ones are made (a new role certificate is
#               signed by the CA already there)
set -euo pipefail

dir="" uid="" days=825 force=0 web_san="DNS:localhost,IP:127.0.0.1,DNS:transtick-web"
while (($#)); do
  case $1 in
    --uid) uid=$2; shift 2 ;;
    --web-host)
      if [[ $2 =~ ^[0-9.]+$ || $2 == *:* ]]; then web_san+=",IP:$2"; else web_san+=",DNS:$2"; fi
      shift 2 ;;
    --days) days=$2; shift 2 ;;
    --force) force=1; shift ;;
    -h | --help) sed -n '2,24p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    -*) echo "make-certs: unknown option $1" >&2; exit 2 ;;
    *) [[ -z $dir ]] || { echo "make-certs: one DIR only" >&2; exit 2; }; dir=$1; shift ;;
  esac
done
[[ -n $dir ]] || { echo "usage: deploy/make-certs.sh DIR [--uid UID] [--days N] [--force]" >&2; exit 2; }
command -v openssl >/dev/null || { echo "make-certs: needs openssl (apt-get install openssl)" >&2; exit 1; }

mkdir -p "$dir"
cd "$dir"
umask 077
if ((force)); then rm -f ca.crt ca.key ca.srl {root,worker,display,web}.{crt,key} tokens {admin,client}.token; fi

if [[ ! -s ca.key || ! -s ca.crt ]]; then
  openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out ca.key 2>/dev/null
  openssl req -x509 -new -key ca.key -sha256 -days 3650 -subj "/CN=transtick cluster CA" \
    -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,keyCertSign,cRLSign" \
    -out ca.crt 2>/dev/null
  rm -f {root,worker,display,web}.crt  # signed by another CA, if any
fi

for role in root worker display web; do
  [[ -s $role.key && -s $role.crt ]] && continue
  openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$role.key" 2>/dev/null
  openssl req -new -key "$role.key" -subj "/CN=transtick-$role" -out "$role.csr" 2>/dev/null
  san="DNS:transtick-$role" usage="serverAuth,clientAuth"
  if [[ $role == web ]]; then san=$web_san usage=serverAuth; fi
  printf '%s\n' "subjectAltName=$san" "basicConstraints=critical,CA:FALSE" \
    "keyUsage=critical,digitalSignature" "extendedKeyUsage=$usage" >"$role.ext"
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

chmod 644 ca.crt root.crt worker.crt display.crt web.crt
chmod 600 ca.key root.key worker.key display.key web.key tokens admin.token client.token
# The daemons' files go to the image's user; the client tokens stay the caller's.
if [[ -n $uid ]]; then chown "$uid" root.key worker.key display.key web.key tokens; fi
echo "make-certs: $(pwd): CA, root/worker/display/web certificates and tokens ready" >&2

#!/usr/bin/env bash
# Makes a throwaway CA and a worker certificate for the name `reliefboard-worker` (the
# visualization node dials workers by address and checks this name with --tls-domain):
#
#   deploy/make-certs.sh DIR     writes DIR/ca.pem, DIR/worker.pem, DIR/worker.key
#
# For trying TLS out and for deploy/test-compose.sh --tls; real deployments use their own CA.
set -euo pipefail
dir=${1:?usage: $0 DIR}
mkdir -p "$dir"
cd "$dir"
openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -days 7 \
  -subj "/CN=reliefboard test CA" -keyout ca.key -out ca.pem 2>/dev/null
openssl req -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes \
  -subj "/CN=reliefboard-worker" -keyout worker.key -out worker.csr 2>/dev/null
printf 'subjectAltName=DNS:reliefboard-worker\nbasicConstraints=CA:FALSE\nkeyUsage=digitalSignature\nextendedKeyUsage=serverAuth\n' >worker.ext
openssl x509 -req -in worker.csr -CA ca.pem -CAkey ca.key -CAcreateserial -days 7 \
  -extfile worker.ext -out worker.pem 2>/dev/null
rm -f worker.csr worker.ext ca.srl ca.key
# The containers run as an unprivileged user that must read the key.
chmod 0644 worker.key
echo "wrote $dir/ca.pem, worker.pem, worker.key"

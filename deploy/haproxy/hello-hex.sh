#!/usr/bin/env bash
# Prints, as hex, the HELLO frame that HAProxy's health check sends first (docs/protocol.md
# sections 2 and 5.1): magic "SGMQ", version 1, type 0x0001, payload = u32 length + token bytes,
# little endian. The token is read like segmatch-server reads it (trailing whitespace is not part
# of it). Without a token file the token is empty: a server without --token-file answers any
# HELLO with HELLO_OK, so one health check serves both kinds of replica.
# Usage: deploy/haproxy/hello-hex.sh [TOKEN_FILE]
#        export SEGMATCH_HELLO_HEX="$(deploy/haproxy/hello-hex.sh /etc/segmatch/token)"
set -euo pipefail
export LC_ALL=C
token=""
if [ $# -ge 1 ] && [ -n "$1" ]; then
  [ -r "$1" ] || { echo "hello-hex.sh: cannot read token file $1" >&2; exit 2; }
  token="$(cat -- "$1"; printf x)"
  token="${token%x}"
  token="${token%"${token##*[![:space:]]}"}"
  [ -n "$token" ] || { echo "hello-hex.sh: token file $1 is empty" >&2; exit 2; }
fi
n=${#token}
u32le() { printf '%02x%02x%02x%02x' $(($1 & 255)) $((($1 >> 8) & 255)) $((($1 >> 16) & 255)) $((($1 >> 24) & 255)); }
printf '53474d51'   # "SGMQ"
printf '0100'       # protocol version 1
printf '0100'       # HELLO
u32le $((4 + n))    # payload length
u32le "$n"          # token length
[ "$n" -eq 0 ] || printf '%s' "$token" | od -An -v -tx1 | tr -d ' \n'
printf '\n'

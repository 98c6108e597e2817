# tests/cluster_lib.sh: the engines of a scale-out cluster on loopback, started by the caller
# itself and torn down at exit (sourced after test_lib.sh, which provides WORK and cleanup):
#   start_postgres  initdb + pg_ctl on a Unix socket under WORK; sets QUEUE (a postgres:// URI)
#   start_s3 BUCKET the S3 test server (moto with SigV4 checking, common/store/testing/
#                   s3_test_server.py); sets S3_ENDPOINT, exports AWS_ACCESS_KEY_ID and
#                   AWS_SECRET_ACCESS_KEY (the only way our binaries take S3 credentials) and sets
#                   STORE_URI=s3://BUCKET/cluster?endpoint=...&query_slash=literal
CLUSTER_SRC=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)

start_postgres() {
  chmod 755 "$WORK"  # the PostgreSQL server runs as the postgres user
  PGBIN=$(ls -d /usr/lib/postgresql/*/bin 2>/dev/null | sort -V | tail -n 1)
  [ -x "$PGBIN/initdb" ] || { echo "FAIL: no PostgreSQL server (scripts/install-deps.sh installs postgresql-15)"; exit 1; }
  PG_AS=""
  if [ "$(id -u)" = 0 ]; then PG_AS="runuser -u postgres --"; fi
  mkdir -p "$WORK/pg" && { [ -z "$PG_AS" ] || chown postgres: "$WORK/pg"; }
  $PG_AS "$PGBIN/initdb" -D "$WORK/pg/data" -U postgres --auth=trust --no-sync >"$WORK/initdb.log" 2>&1 ||
    { echo "FAIL: initdb"; cat "$WORK/initdb.log"; exit 1; }
  $PG_AS "$PGBIN/pg_ctl" -D "$WORK/pg/data" -l "$WORK/pg/server.log" -w -t 60 \
    -o "-c listen_addresses='' -c unix_socket_directories='$WORK/pg' -c fsync=off -p 5433" start >/dev/null ||
    { echo "FAIL: pg_ctl start"; cat "$WORK/pg/server.log"; exit 1; }
  trap 'stop_cluster_engines; cleanup' EXIT
  # If this shell is killed outright (ctest's timeout sends SIGKILL: no trap runs), a reaper kills
  # the servers, stops PostgreSQL and removes WORK: it waits on a FIFO whose only writer is this shell (servers are
  # started without it, test_lib.sh `start`), so it wakes exactly when the shell is gone.
  mkfifo "$WORK/alive"
  (
    trap '' INT TERM
    read -r _ <"$WORK/alive"
    pkill -9 -f -- "$WORK/" 2>/dev/null  # the servers started with --data under WORK
    $PG_AS "$PGBIN/pg_ctl" -D "$WORK/pg/data" -m immediate -w stop >/dev/null 2>&1
    rm -rf "$WORK"
  ) 8>&- 9>&- &
  exec 9>"$WORK/alive"
  QUEUE="postgresql:///postgres?host=$WORK/pg&port=5433&user=postgres"
}

start_s3() {
  mkfifo "$WORK/s3.in" "$WORK/s3.out"
  python3 "$CLUSTER_SRC/common/store/testing/s3_test_server.py" "$1" <"$WORK/s3.in" >"$WORK/s3.out" 2>"$WORK/s3.log" 9>&- &
  PIDS+=("$!")
  exec 8>"$WORK/s3.in"  # the server's standard input: it stops when this closes
  local ready
  read -r ready S3_ENDPOINT S3_BUCKET AWS_ACCESS_KEY_ID AWS_SECRET_ACCESS_KEY <"$WORK/s3.out"
  [ "$ready" = READY ] || { echo "FAIL: the S3 test server did not start"; cat "$WORK/s3.log"; exit 1; }
  export AWS_ACCESS_KEY_ID AWS_SECRET_ACCESS_KEY
  # query_slash=literal: moto's signature check wants '/' unencoded in query values (s3_client.h)
  STORE_URI="s3://$S3_BUCKET/cluster?endpoint=$S3_ENDPOINT&query_slash=literal"
}

# Objects under the cluster prefix of the bucket (python3 + boto3, as the image has them).
s3_count() {
  python3 -c "
import boto3
s3 = boto3.client('s3', endpoint_url='$S3_ENDPOINT', region_name='us-east-1')
n = 0
for page in s3.get_paginator('list_objects_v2').paginate(Bucket='$S3_BUCKET'):  # moto: no '/' in Prefix
    n += sum(o['Key'].startswith('cluster/$1') for o in page.get('Contents', []))
print(n)"
}

stop_cluster_engines() {
  exec 8>&- 9>&- 2>/dev/null
  [ -n "${PGBIN:-}" ] && $PG_AS "$PGBIN/pg_ctl" -D "$WORK/pg/data" -m immediate -w stop >/dev/null 2>&1
  return 0
}

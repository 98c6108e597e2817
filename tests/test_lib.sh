# tests/test_lib.sh: helpers shared by the shell integration tests (sourced; needs BIN set to the
# instascene command). Creates WORK (removed at exit with every process started by `start`) and
# counts checks in `passed` / `failed`.
WORK=$(mktemp -d)
PIDS=()
cleanup() {
  for p in "${PIDS[@]}"; do kill -9 "$p" 2>/dev/null; done
  rm -rf "$WORK"
}
trap cleanup EXIT
passed=0
failed=0
check() {  # check NAME COMMAND...: the command must succeed
  local name=$1; shift
  if "$@" >"$WORK/cmd.txt" 2>"$WORK/err.txt"; then passed=$((passed + 1)); cp "$WORK/cmd.txt" "$WORK/out.txt"; else
    failed=$((failed + 1)); echo "FAIL: $name"; cat "$WORK/err.txt"; tail -n 20 "$WORK"/*.log 2>/dev/null; fi
}
check_fails() {  # check_fails NAME PATTERN COMMAND...: must fail with PATTERN on stderr
  local name=$1 pattern=$2; shift 2
  if "$@" >"$WORK/cmd.txt" 2>"$WORK/err.txt"; then failed=$((failed + 1)); echo "FAIL (succeeded): $name"
  elif grep -q "$pattern" "$WORK/err.txt"; then passed=$((passed + 1)); else
    failed=$((failed + 1)); echo "FAIL (wrong message): $name"; cat "$WORK/err.txt"; fi
}
# start NAME READYFILE COMMAND...: runs a server in the background, waits for its ready file.
start() {
  local name=$1 ready=$2; shift 2
  rm -f "$ready"
  "$@" >"$WORK/$name.log" 2>&1 8>&- 9>&- &  # not the cluster engines' lifeline FIFOs (cluster_lib.sh)
  LAST_PID=$!
  PIDS+=("$LAST_PID")
  for _ in $(seq 200); do [ -s "$ready" ] && return 0; sleep 0.05; done
  echo "FAIL: $name did not become ready"; cat "$WORK/$name.log"; failed=$((failed + 1)); return 1
}
# job_field ADDR ID FIELD: one field of a job from `instascene jobs --json`.
job_field() {
  "$BIN" jobs --server "$1" --json --limit 1000 2>/dev/null | tail -n 1 |
    python3 -c "import json,sys; d=json.load(sys.stdin); print([j for j in d['jobs'] if j['id']=='$2'][0]['$3'])"
}
# wait_state ADDR ID STATE [PHASE]: polls until the job is in STATE (and its progress in PHASE).
wait_state() {
  for _ in $(seq 300); do  # 30 s at most
    if [ "$(job_field "$1" "$2" state)" = "$3" ] && { [ -z "${4:-}" ] || [ "$(job_field "$1" "$2" phase)" = "$4" ]; }; then return 0; fi
    sleep 0.1
  done
  return 1
}
json_get() {  # json_get FILE EXPR: evaluates EXPR on the JSON of FILE's last line as d
  tail -n 1 "$1" | python3 -c "import json,sys; d=json.load(sys.stdin); print($2)"
}


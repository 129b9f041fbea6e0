#!/usr/bin/env bash
# scripts/slurm_study.sh on a real single-node Slurm cluster (Debian 12: slurmctld, slurmd,
# slurm-client, munge). The test starts munged, slurmctld and slurmd itself (PID 1 is no
# systemd), as root, on localhost, with every file (keys, sockets, state, spool, logs) in its own
# mktemp directory and ports chosen free at run time, so it can run beside other tests. Then:
#   1. a study in 3 shards: the merged summary.csv and summary.md are byte-identical to a
#      single-machine run;
#   2. a study whose shard 2 fails: that array task FAILED, the merge stays pending with reason
#      DependencyNeverSatisfied, and no merged output appears;
#   3. a shard requeued while it runs, released from Slurm's requeue hold at once: it resumes
#      from its runs.jsonl, runs nothing twice, and its log keeps both attempts.
# Every daemon is stopped by its pid, on failure too (trap).
#
# Usage: study_slurm_cluster_test.sh CARMBA_BIN SOURCE_DIR
# Exit codes: 0 passed, 1 failed, 77 skipped (the Slurm or munge packages are not installed).
set -euo pipefail

export CARMBA="$1"  # scripts/slurm_study.sh and its array tasks run it
SRC="$2"
SKIP=77

for tool in munged slurmctld slurmd sbatch squeue sinfo scontrol scancel python3; do
  if ! command -v "$tool" > /dev/null 2>&1 && [[ ! -x "/usr/sbin/$tool" ]]; then
    echo "SKIP: $tool not installed (scripts/setup.sh installs slurmctld slurmd slurm-client munge)"
    exit "$SKIP"
  fi
done
PATH="$PATH:/usr/sbin"
if [[ "$(id -u)" != 0 ]]; then
  echo "SKIP: the daemons run as root (SlurmUser=SlurmdUser=root); not root here"
  exit "$SKIP"
fi

T0=$SECONDS
# The whole test is bounded: every wait ends by this deadline (the issue's 3 minutes on 2 cores,
# less the daemons' stop), whatever its own limit; ctest's TIMEOUT (180 s) is the backstop.
BUDGET_S=165
D=$(mktemp -d "${TMPDIR:-/tmp}/carmba_slurm_cluster_XXXXXX")
chmod 755 "$D"  # munged wants its socket's directories searchable by all
PIDS=()         # daemons, stopped in reverse order

fail() {
  echo "FAIL: $*" >&2
  exit 1
}
log() { echo "[$((SECONDS - T0)) s] $*"; }

stop_daemons() {
  local code=$?
  set +e
  if [[ -n "${SLURM_CONF:-}" && -f "$SLURM_CONF" ]]; then
    timeout 10 scancel --quiet --user=root 2> /dev/null
  fi
  for ((i = ${#PIDS[@]} - 1; i >= 0; i--)); do kill "${PIDS[i]}" 2> /dev/null; done
  for pid in "${PIDS[@]}"; do
    for _ in $(seq 100); do kill -0 "$pid" 2> /dev/null || break; sleep 0.1; done
    kill -KILL "$pid" 2> /dev/null
    wait "$pid" 2> /dev/null
  done
  if [[ $code == 0 ]]; then
    rm -rf "$D"
  else
    echo "kept $D for inspection; daemon logs:" >&2
    tail -n 20 "$D"/*.log "$D"/munge/log 2> /dev/null >&2
  fi
  exit "$code"
}
trap stop_daemons EXIT

# Waits until `$@` succeeds, at most $TIMEOUT seconds (default 60) and never past the test's
# budget, polling every 0.2 s.
wait_for() {
  local deadline=$((SECONDS + ${TIMEOUT:-60}))
  ((deadline <= T0 + BUDGET_S)) || deadline=$((T0 + BUDGET_S))
  until "$@"; do
    ((SECONDS < deadline)) || return 1
    sleep 0.2
  done
}

free_port() {
  python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'
}

start_cluster() {
  mkdir -p "$D/munge" "$D/state" "$D/spool"
  chmod 755 "$D/munge"
  head -c 1024 /dev/urandom > "$D/munge/munge.key"
  chmod 400 "$D/munge/munge.key"
  munged --foreground --socket="$D/munge/sock" --key-file="$D/munge/munge.key" \
    --pid-file="$D/munge/munged.pid" --log-file="$D/munge/log" --seed-file="$D/munge/seed" \
    > "$D/munged.out" 2>&1 &
  PIDS+=($!)
  TIMEOUT=10 wait_for test -S "$D/munge/sock" || fail "munged did not create its socket"

  local host node ctld_port slurmd_port
  host=$(hostname -s)
  node=$(slurmd -C | head -n 1)  # NodeName=<host> CPUs=... RealMemory=...
  ctld_port=$(free_port)
  slurmd_port=$(free_port)
  while [[ "$slurmd_port" == "$ctld_port" ]]; do slurmd_port=$(free_port); done
  cat > "$D/slurm.conf" << EOF
ClusterName=carmba$$
SlurmctldHost=$host(127.0.0.1)
SlurmUser=root
SlurmdUser=root
SlurmctldPort=$ctld_port
SlurmdPort=$slurmd_port
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$D/munge/sock
StateSaveLocation=$D/state
SlurmdSpoolDir=$D/spool
SlurmctldPidFile=$D/slurmctld.pid
SlurmdPidFile=$D/slurmd.pid
SlurmctldLogFile=$D/slurmctld.log
SlurmdLogFile=$D/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SchedulerType=sched/backfill
MpiDefault=none
ReturnToService=2
JobCompType=jobcomp/none
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
$node NodeAddr=127.0.0.1 State=UNKNOWN
PartitionName=carmba Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
  export SLURM_CONF="$D/slurm.conf"
  slurmctld -D -c -f "$SLURM_CONF" > "$D/slurmctld.out" 2>&1 &
  PIDS+=($!)
  slurmd -D -f "$SLURM_CONF" -N "$host" > "$D/slurmd.out" 2>&1 &
  PIDS+=($!)
  node_idle() { [[ "$(sinfo -h -N -o %t 2> /dev/null)" == idle ]]; }
  TIMEOUT=60 wait_for node_idle || fail "the node did not become idle within 60 s"
  log "cluster up: node $host idle (slurmctld port $ctld_port, slurmd port $slurmd_port)"
}

# Field NAME=value of `scontrol show job JOB`.
job_field() { scontrol -o show job "$1" 2> /dev/null | tr ' ' '\n' | sed -n "s/^$2=//p" | head -n 1; }
no_jobs_left() { [[ -z "$(squeue -h -o %i 2> /dev/null)" ]]; }
# Until no job is left or the merge job (in submit output $1) can never start.
merge_done_or_blocked() {
  no_jobs_left || [[ "$(squeue -h -j "$(merge_id_of "$1")" -o %r 2> /dev/null)" == DependencyNeverSatisfied ]]
}
# Fails with the shards' logs when a merge job (in submit output $1) can never start.
check_merge_not_blocked() {
  if ! no_jobs_left; then
    fail "a shard failed, the merge is blocked; shard logs: $(cat "$2"/logs/shard-*.out)"
  fi
}
# The array job id printed by slurm_study.sh ("submitted array job N (...)").
array_id_of() { sed -n 's/^submitted array job \([0-9]*\).*/\1/p' "$1"; }
merge_id_of() { sed -n 's/^submitted merge job \([0-9]*\).*/\1/p' "$1"; }

# study NAME TRIALS PROBLEMS_YAML: a study of the simulated thesis object.
write_study() {
  cat > "$D/$1.yaml" << EOF
name: $1
trials: $2
base_seed: 5
problems:
$3
configs:
  - {name: posit_ba, file: $SRC/configs/posit_ba_analytic.yaml}
sweeps:
  pixel_noise_px: [0.2, 0.6, 1.0]
EOF
}
RQ_TRIALS=1000
RQ_SHARD_RUNS=$((3 * RQ_TRIALS / 2))
SIM="{camera: $SRC/data/thesis/camera.json, markers: thesis}"

check_shards_merge_to_the_whole_study() {
  write_study whole 4 "  - {name: sim, synthetic: $SIM}
  - {name: sim_few_views, synthetic: {camera: $SRC/data/thesis/camera.json, markers: thesis, view_angles_deg: [0, 20, 45], pairs: [[0, 2]]}}"
  CPUS_PER_TASK=1 TIME_PER_TASK=00:05:00 bash "$SRC/scripts/slurm_study.sh" "$D/whole.yaml" \
    "$D/out" 3 > "$D/submit.txt"
  cat "$D/submit.txt"
  TIMEOUT=120 wait_for merge_done_or_blocked "$D/submit.txt" ||
    fail "the shards and the merge did not finish in 120 s"
  check_merge_not_blocked "$D/submit.txt" "$D/out"
  local array
  array=$(array_id_of "$D/submit.txt")
  for k in 1 2 3; do
    [[ "$(job_field "${array}_$k" JobState)" == COMPLETED ]] ||
      fail "array task $k: $(job_field "${array}_$k" JobState), expected COMPLETED"
  done
  [[ -f "$D/out/merged/summary.csv" ]] || fail "no merged summary.csv; merge log: $(cat "$D/out/logs/merge.out")"
  "$CARMBA" study --study="$D/whole.yaml" --out="$D/single" --jobs=2 > "$D/single.txt"
  cmp "$D/out/merged/summary.csv" "$D/single/summary.csv" ||
    fail "merged summary.csv differs from the single-machine run"
  cmp "$D/out/merged/summary.md" "$D/single/summary.md" ||
    fail "merged summary.md differs from the single-machine run: $(diff "$D/out/merged/summary.md" "$D/single/summary.md" | head -n 5)"
  log "1. 3 shards merged: summary.csv ($(wc -l < "$D/single/summary.csv") lines) and summary.md" \
    "($(wc -l < "$D/single/summary.md") lines) byte-identical to the single-machine run"
}

check_failed_shard_blocks_the_merge() {
  # Run i goes to shard (i mod 3) + 1: with one run per problem, shard 2 gets only `lost`'s run,
  # which fails (no such problem file).
  cat > "$D/failing.yaml" << EOF
name: failing
trials: 1
problems:
  - {name: good, synthetic: $SIM}
  - {name: lost, file: $D/no_such_problem.yaml}
  - {name: good_too, synthetic: $SIM}
configs:
  - {name: posit_ba, file: $SRC/configs/posit_ba_analytic.yaml}
EOF
  CPUS_PER_TASK=1 bash "$SRC/scripts/slurm_study.sh" "$D/failing.yaml" "$D/failing" 3 \
    > "$D/submit_failing.txt"
  local array merge
  array=$(array_id_of "$D/submit_failing.txt")
  merge=$(merge_id_of "$D/submit_failing.txt")
  never_satisfied() { [[ "$(squeue -h -j "$merge" -o %r 2> /dev/null)" == DependencyNeverSatisfied ]]; }
  TIMEOUT=60 wait_for never_satisfied ||
    fail "merge job $merge: state $(squeue -h -j "$merge" -o '%T %r'), expected PENDING DependencyNeverSatisfied"
  [[ "$(job_field "${array}_2" JobState)" == FAILED ]] ||
    fail "array task 2: $(job_field "${array}_2" JobState), expected FAILED"
  [[ "$(job_field "${array}_2" ExitCode)" == 1:0 ]] ||
    fail "array task 2: exit code $(job_field "${array}_2" ExitCode), expected 1:0"
  for k in 1 3; do
    [[ "$(job_field "${array}_$k" JobState)" == COMPLETED ]] ||
      fail "array task $k: $(job_field "${array}_$k" JobState), expected COMPLETED"
  done
  grep -q "1 of 1 runs failed: '.*no_such_problem.yaml" "$D/failing/logs/shard-2.out" ||
    fail "shard 2's log does not say why it failed: $(cat "$D/failing/logs/shard-2.out")"
  [[ ! -e "$D/failing/merged" ]] || fail "merged output appeared although shard 2 failed"
  scancel "$merge"
  log "2. shard 2 failed (FAILED, exit 1:0, reason in its log); merge $merge pending" \
    "(DependencyNeverSatisfied), no merged output"
}

check_requeued_shard_resumes() {
  # 2 shards of 3 x $RQ_TRIALS runs of a few ms each: shard 1 runs for seconds, long enough to
  # be requeued in the middle.
  write_study requeue "$RQ_TRIALS" "  - {name: sim, synthetic: $SIM}"
  CPUS_PER_TASK=1 bash "$SRC/scripts/slurm_study.sh" "$D/requeue.yaml" "$D/rq" 2 \
    > "$D/submit_requeue.txt"
  local array runs_log="$D/rq/shard-1/runs.jsonl" before
  array=$(array_id_of "$D/submit_requeue.txt")
  some_runs_done() { [[ -f "$runs_log" && $(wc -l < "$runs_log") -ge 20 ]]; }
  TIMEOUT=60 wait_for some_runs_done || fail "shard 1 recorded no runs within 60 s"
  scontrol requeue "${array}_1"
  local t_requeue=$SECONDS
  before=$(wc -l < "$runs_log")
  ((before < $RQ_SHARD_RUNS)) || fail "shard 1 had finished ($before runs) before it was requeued; make it longer"
  requeue_held() { [[ "$(squeue -h -j "${array}_1" -o %T 2> /dev/null)" == PENDING ]]; }
  TIMEOUT=30 wait_for requeue_held || fail "requeued shard 1 is not pending"
  log "3. shard 1 requeued after $before of $RQ_SHARD_RUNS runs; pending with reason" \
    "$(squeue -h -j "${array}_1" -o %r), start time $(squeue -h -j "${array}_1" -o %S); released now"
  # slurmd revokes the killed attempt's credential; a new one issued within the same second
  # counts as revoked too ("Job credential revoked": the task then fails). Released 2 s after
  # the requeue, the task starts.
  while ((SECONDS < t_requeue + 2)); do sleep 0.2; done
  scontrol update JobId="${array}_1" StartTime=now
  TIMEOUT=120 wait_for merge_done_or_blocked "$D/submit_requeue.txt" ||
    fail "the requeued study did not finish in 120 s"
  check_merge_not_blocked "$D/submit_requeue.txt" "$D/rq"
  log "   requeued shard and merge finished $((SECONDS - t_requeue)) s after the requeue"
  [[ "$(job_field "${array}_1" Restarts)" == 1 ]] ||
    fail "shard 1: Restarts=$(job_field "${array}_1" Restarts), expected 1"
  local shard_log="$D/rq/logs/shard-1.out"
  [[ $(grep -c "^slurm_study.sh: shard 1/2 attempt" "$shard_log") == 2 ]] ||
    fail "shard 1's log does not keep both attempts: $(cat "$shard_log")"
  grep -q "^slurm_study.sh: shard 1/2 attempt 2" "$shard_log" || fail "no second attempt in the log"
  local summary done_before run_now
  summary=$(grep "^study requeue (shard 1/2)" "$shard_log" | tail -n 1)
  done_before=$(sed -n 's/.* \([0-9]*\) already done, \([0-9]*\) run now.*/\1/p' <<< "$summary")
  run_now=$(sed -n 's/.* \([0-9]*\) already done, \([0-9]*\) run now.*/\2/p' <<< "$summary")
  [[ -n "$done_before" && -n "$run_now" ]] || fail "no resume summary in shard 1's log: $(cat "$shard_log")"
  ((done_before >= before && done_before > 0 && run_now > 0 && done_before + run_now == $RQ_SHARD_RUNS)) ||
    fail "resume: $done_before already done + $run_now run now, expected ~$before + the rest = $RQ_SHARD_RUNS"
  local lines unique
  lines=$(wc -l < "$runs_log")
  unique=$(python3 -c 'import json, sys; print(len({json.loads(l)["key"] for l in open(sys.argv[1])}))' "$runs_log")
  [[ $lines == $RQ_SHARD_RUNS && $unique == $RQ_SHARD_RUNS ]] ||
    fail "shard 1's runs.jsonl: $lines lines, $unique distinct runs, expected $RQ_SHARD_RUNS of each"
  [[ -f "$D/rq/merged/summary.csv" ]] || fail "no merged output after the requeue"
  log "   resumed: $done_before already done, $run_now run now; runs.jsonl $lines lines," \
    "$unique distinct runs; log keeps both attempts; merged"
}

start_cluster
check_shards_merge_to_the_whole_study
check_failed_shard_blocks_the_merge
check_requeued_shard_resumes
log "passed"

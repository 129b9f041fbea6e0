#!/usr/bin/env bash
# Runs a carmba accuracy study on a Slurm cluster as a job array: one array task per shard, and
# a merge job that starts when every task has succeeded. Slurm does the scheduling, requeueing and
# accounting; carmba only splits the runs deterministically (`--shard K/N`: run i goes to shard
# (i mod N) + 1, whatever the machine or the number of cores) and merges the shard directories.
#
# Usage, on a login node, from the repository root with carmba built:
#   scripts/slurm_study.sh STUDY_YAML OUT_DIR NUM_SHARDS [extra sbatch options...]
#   e.g.  scripts/slurm_study.sh configs/studies/noise_sweep.yaml /scratch/$USER/noise 16 \
#             --partition=cpu --account=myproject
#
# It submits:
#   1. an array job of NUM_SHARDS tasks (--array=1-N). Task K runs
#        carmba study --study STUDY_YAML --out OUT_DIR/shard-K --shard K/N \
#                     --jobs $SLURM_CPUS_PER_TASK --resume --no-plots
#      (a shard's report.html has no plots: the merged report draws them from all runs).
#      Each run inside is single-threaded, so --cpus-per-task cores are used in parallel.
#      The task's exit code is carmba study's: a shard with failed runs (beyond the study's
#      allow_failures) exits 1 and is a FAILED array task, so the merge never starts.
#      --resume makes a requeued or preempted task (sbatch --requeue) skip the runs it already
#      recorded in OUT_DIR/shard-K/runs.jsonl instead of starting over; its log
#      OUT_DIR/logs/shard-K.out is appended to (--open-mode=append), one "attempt" line per
#      start. Slurm holds a requeued job for about two minutes before it may start again
#      (reason BeginTime); `scontrol update JobId=<job>_<K> StartTime=now` releases it at once
#      (wait a second or two after the requeue: a restart within the second of the kill is
#      refused by slurmd, "Job credential revoked", and the task fails).
#      A task that failed can be re-submitted alone with  sbatch --array=K ... and resumes the
#      same way.
#   2. a merge job with --dependency=afterok:<array job id> running
#        carmba study-merge --out OUT_DIR/merged --shards 'OUT_DIR/shard-*'
#      which checks that all shards belong to the same study (fingerprint: the run list, carmba's
#      version and the content of every file the runs read) and that no run is missing, and
#      writes OUT_DIR/merged/{runs.jsonl,summary.csv,summary.md,timing.csv,report.html}:
#      summary.csv and summary.md are byte-identical to a single-machine run of the whole study
#      (tests/cli/study_slurm_cluster_test.sh checks it on a real Slurm); timing.csv and
#      report.html hold wall-clock times and differ.
#      If a shard fails, the merge job stays pending (reason DependencyNeverSatisfied): cancel it,
#      fix the cause, re-submit the shard, then the merge.
#
# Environment: CARMBA (path of the carmba binary, default build/bin/carmba), CPUS_PER_TASK
# (default 4), TIME_PER_TASK (default 01:00:00). The array tasks call this script back with
# --task; you do not need to.
set -euo pipefail

CARMBA="${CARMBA:-build/bin/carmba}"

if [[ "${1:-}" == "--task" ]]; then
  # Inside an array task: $2 study, $3 out dir, $4 number of shards.
  study="$2"; out="$3"; shards="$4"
  k="${SLURM_ARRAY_TASK_ID:?not inside a Slurm array task}"
  echo "slurm_study.sh: shard $k/$shards attempt $((${SLURM_RESTART_COUNT:-0} + 1)) (job" \
    "${SLURM_JOB_ID:-?}) on $(hostname) at $(date -u +%FT%TZ)"
  exec "$CARMBA" study --study="$study" --out="$out/shard-$k" --shard="$k/$shards" \
    --jobs="${SLURM_CPUS_PER_TASK:-1}" --resume --no-plots
fi

if [[ $# -lt 3 ]]; then
  sed -n '2,/^set -euo/p' "$0" | sed 's/^# \{0,1\}//' | head -n -1 >&2
  exit 2
fi
study="$1"; out="$2"; shards="$3"; shift 3
if ! [[ "$shards" =~ ^[1-9][0-9]*$ ]]; then
  echo "slurm_study.sh: NUM_SHARDS must be a positive integer, got '$shards'" >&2
  exit 2
fi
[[ -f "$study" ]] || { echo "slurm_study.sh: $study: no such study file" >&2; exit 2; }
[[ -x "$CARMBA" ]] || { echo "slurm_study.sh: $CARMBA: carmba binary not found (set CARMBA)" >&2; exit 2; }
mkdir -p "$out/logs"

array_id=$(sbatch --parsable \
  --job-name="carmba-study" \
  --array="1-$shards" \
  --cpus-per-task="${CPUS_PER_TASK:-4}" \
  --time="${TIME_PER_TASK:-01:00:00}" \
  --requeue \
  --open-mode=append \
  --output="$out/logs/shard-%a.out" \
  "$@" \
  "$0" --task "$study" "$out" "$shards")
echo "submitted array job $array_id ($shards shards of $study)"

merge_id=$(sbatch --parsable \
  --job-name="carmba-study-merge" \
  --dependency="afterok:$array_id" \
  --cpus-per-task=1 \
  --time=00:30:00 \
  --output="$out/logs/merge.out" \
  "$@" \
  --wrap="'$CARMBA' study-merge --out='$out/merged' --shards='$out/shard-*'")
echo "submitted merge job $merge_id (runs after all shards succeed): results in $out/merged"

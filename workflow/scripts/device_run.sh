# Sourced by the device scripts (gpu_judge.sh, gpu_recipe_ablation.sh, gpu_loop_selftest.sh; gpu_twin_checks.sh for
# device_check_warp alone): one resumable, detached run on the lent device. The device kills a command's processes at
# its 10-min limit, so the run lives in its own process session (setsid) and outlives the command; LIMIT_S (default 0:
# until done) is how long a call waits for it. The same command again re-attaches to a run still going
# (OUTDIR/NAME.pid) or, once it ended, starts the next one, which resumes (Snakemake keeps finished jobs and redoes a
# cut one; the loop's studies go on).
#   device_attach OUT NAME          status 0, DEVICE_PID set: a run is still going (a second call never starts one)
#   device_unlock WHO PROFILE       a killed Snakemake's lock is taken over; exit 4 while another Snakemake runs here
#   device_touch_mesh PROFILE       the carried mesh newer than its conf, so rule mesh (gmsh) never reruns
#   device_start OUT NAME CMD...    CMD detached: output appended to OUT/NAME.log, status to OUT/NAME.rc
#   device_wait OUT NAME            wait; DEVICE_RC = the run's status, 75 while it still runs
#   device_progress OUT NAME [N]    the log's last N (4) lines of progress
#   device_check_warp WHO DEVICE [MODULE...]  import Warp (and MODULEs), print its version and CUDA devices;
#                                   status 3 when an import fails, or when DEVICE is cuda and Warp sees no CUDA device

device_attach() {
  DEVICE_PID=$(cat "$1/$2.pid" 2>/dev/null)
  [ -n "$DEVICE_PID" ] && kill -0 "$DEVICE_PID" 2>/dev/null || return 1
  echo "already running (pid $DEVICE_PID): re-attaching; progress:"
  device_progress "$1" "$2" 1
  return 0  # attached, even while the log has no progress line yet (grep's status must not leak out)
}

device_unlock() {
  [ -n "$(ls -A .snakemake/locks 2>/dev/null)" ] || return 0
  local p
  for p in $(pgrep -f "snakemake --workflow-profile"); do  # its working folder: another checkout's run is no matter
    if [ "$(readlink "/proc/$p/cwd")" = "$PWD" ]; then
      echo "$1: another Snakemake run (pid $p) holds this checkout's lock; run this one in its own copy of the" \
        "checkout (docs/slides.md, \"Paper-profile run\")" >&2
      exit 4
    fi
  done
  python3 -m snakemake --workflow-profile "workflow/profiles/$2" --unlock > /dev/null 2>&1
}

device_touch_mesh() {
  # touched once, before a run starts: a resumed run does not see it change under the jobs already done
  local res c
  res=$(sed -n 's/^twin_resolution: *\([a-z]*\).*/\1/p' "conf/workflow/$1.yaml")
  for c in conf/mesh.yaml "conf/twin/mesh/$res.yaml"; do
    [ -f "results/twin/mesh_$res.npz" ] && [ "$c" -nt "results/twin/mesh_$res.npz" ] &&
      touch "results/twin/mesh_$res.npz" "results/twin/mesh_$res.json"
  done
  return 0
}

device_start() {
  local out=$1 name=$2
  shift 2
  rm -f "$out/$name.rc"
  touch "$out/$name.log"
  setsid bash -c '"${@:3}" >> "$1/$2.log" 2>&1; echo $? > "$1/$2.rc"' _ "$out" "$name" "$@" \
    < /dev/null > /dev/null 2>&1 &
  DEVICE_PID=$!
  echo "$DEVICE_PID" > "$out/$name.pid"
}

device_wait() {
  local start waited
  start=$(date +%s)
  while kill -0 "$DEVICE_PID" 2>/dev/null; do
    [ "${LIMIT_S:-0}" -gt 0 ] && [ $(( $(date +%s) - start )) -ge "$LIMIT_S" ] && break
    sleep 1
  done
  waited=$(( $(date +%s) - start ))
  if kill -0 "$DEVICE_PID" 2>/dev/null; then
    DEVICE_RC=75
    echo "still running (pid $DEVICE_PID) after waiting $waited s: run the same command again on this warm" \
      "machine to wait for it"
  else
    DEVICE_RC=$(cat "$1/$2.rc" 2>/dev/null || echo 1)
    rm -f "$1/$2.pid"
    echo "$2 rc=$DEVICE_RC after waiting $waited s"
  fi
}

device_progress() {
  grep -E "steps \(|Nothing to be done|Error|Exiting|done in" "$1/$2.log" 2>/dev/null | tail -"${3:-4}"
}

device_check_warp() {
  # one python3 process: the same interpreter the run will use, so a missing package shows before the run starts
  local who=$1 device=$2 mods="" m
  shift 2
  for m in "$@"; do mods+=", $m"; done
  python3 -c "import sys, warp as wp$mods; wp.init(); print('warp', wp.__version__, wp.get_cuda_devices())
sys.exit('$who, and Warp sees no CUDA device' if '$device' == 'cuda' and not wp.get_cuda_devices() else 0)" || return 3
}

"""workflow/scripts/device_run.sh, the detached resumable run the device scripts share: a run outlives the call
that started it, LIMIT_S bounds the wait (75: still running), a second call re-attaches instead of starting
another, and the run's exit status comes back once it ends."""

import os
import subprocess
import sys

from palpation.paths import REPO_ROOT

HELPER = REPO_ROOT / "workflow" / "scripts" / "device_run.sh"
CALL = f"""source {HELPER}
if ! device_attach out job; then device_start out job bash -c "$JOB"; fi
device_wait out job; echo "rc=$DEVICE_RC"; exit $DEVICE_RC"""


def call(tmp_path, job: str, limit_s: int) -> subprocess.CompletedProcess:
    (tmp_path / "out").mkdir(exist_ok=True)
    return subprocess.run(["bash", "-c", CALL], cwd=tmp_path, capture_output=True, text=True, timeout=30,
                          env={**os.environ, "JOB": job, "LIMIT_S": str(limit_s)})


def test_detached_run_reattaches_and_returns_its_status(tmp_path):
    job = "echo '1 of 2 steps (50%) done'; sleep 2; echo started >> starts; exit 3"
    first = call(tmp_path, job, 1)
    assert first.returncode == 75 and "still running" in first.stdout
    pid = (tmp_path / "out/job.pid").read_text().strip()
    again = call(tmp_path, "echo second >> starts", 0)  # re-attaches: the second job never starts
    assert f"already running (pid {pid})" in again.stdout and "1 of 2 steps" in again.stdout
    assert again.returncode == 3 and "rc=3" in again.stdout  # waited until the first run ended
    assert (tmp_path / "starts").read_text() == "started\n" and not (tmp_path / "out/job.pid").exists()
    done = call(tmp_path, "exit 0", 0)  # once it ended, the next call starts the next run
    assert done.returncode == 0 and "already running" not in done.stdout
    assert (tmp_path / "out/job.log").read_text().startswith("1 of 2 steps")  # the log grows over the runs


def test_unlock_refuses_while_another_snakemake_runs_here(tmp_path):
    (tmp_path / ".snakemake/locks").mkdir(parents=True)
    (tmp_path / ".snakemake/locks/0.input.lock").write_text("x")
    other = subprocess.Popen(["bash", "-c", 'exec -a "python3 -m snakemake --workflow-profile x" sleep 30'],
                             cwd=tmp_path)
    try:
        out = subprocess.run(["bash", "-c", f"source {HELPER}; device_unlock me tiny; echo unlocked"], cwd=tmp_path,
                             capture_output=True, text=True, timeout=30)
    finally:
        other.kill()
    assert out.returncode == 4 and "unlocked" not in out.stdout
    assert out.stderr.startswith(f"me: another Snakemake run (pid {other.pid}) holds this checkout's lock")
    assert (tmp_path / ".snakemake/locks/0.input.lock").exists()


def check_warp(tmp_path, args: str, cuda_devices: str) -> subprocess.CompletedProcess:
    """device_check_warp against a stand-in `warp` module (no Warp install or GPU needed) and this python3."""
    (tmp_path / "warp.py").write_text(f"__version__ = '9.9'\ndef init(): pass\n"
                                      f"def get_cuda_devices(): return {cuda_devices}\n")
    (tmp_path / "bin").mkdir(exist_ok=True)
    if not (tmp_path / "bin/python3").exists():
        (tmp_path / "bin/python3").symlink_to(sys.executable)
    env = {**os.environ, "PYTHONPATH": str(tmp_path), "PATH": f"{tmp_path / 'bin'}:{os.environ['PATH']}"}
    return subprocess.run(["bash", "-c", f"source {HELPER}; device_check_warp {args}; echo rc=$?"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=30, env=env)


def test_check_warp_prints_the_devices_and_refuses_cuda_without_one(tmp_path):
    ok = check_warp(tmp_path, "me cpu json", "[]")
    assert "warp 9.9 []" in ok.stdout and "rc=0" in ok.stdout
    no_gpu = check_warp(tmp_path, "'me: the paper profile runs on cuda' cuda", "[]")
    assert "rc=3" in no_gpu.stdout
    assert "me: the paper profile runs on cuda, and Warp sees no CUDA device" in no_gpu.stderr
    gpu = check_warp(tmp_path, "me cuda", "['cuda:0']")
    assert "warp 9.9 ['cuda:0']" in gpu.stdout and "rc=0" in gpu.stdout
    missing = check_warp(tmp_path, "me cpu no_such_module", "[]")
    assert "rc=3" in missing.stdout and "No module named 'no_such_module'" in missing.stderr

"""A job killed during a forced rerun is redone by a plain `snakemake` (palpation.killed_jobs)."""

import base64
import subprocess
import sys
import textwrap

from palpation.killed_jobs import killed_outputs, marked_incomplete
from palpation.paths import REPO_ROOT


def mark(workdir, path: str, max_len: int = 255):
    """An incomplete mark as Snakemake writes it (long names cut into '@' folders)."""
    b64 = base64.urlsafe_b64encode(path.encode()).decode()
    parts = [b64[i:i + max_len - 1] for i in range(0, len(b64), max_len - 1)]
    target = workdir.joinpath(".snakemake", "incomplete", *["@" + p for p in parts[:-1]], parts[-1])
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text('{"external_jobid": null}')


def test_missing_marked_outputs_are_requested(tmp_path):
    long = "results/train/" + "x" * 300 + "/metrics.json"
    for path in ("results/train/A-to-B/L5/seed0/metrics.json", "results/present.txt", long):
        mark(tmp_path, path)
    (tmp_path / "results").mkdir()
    (tmp_path / "results/present.txt").write_text("ok")  # an existing output: --rerun-incomplete's job
    (tmp_path / ".snakemake/incomplete/migration_underway").write_text("")
    assert len(marked_incomplete(tmp_path)) == 3
    assert killed_outputs(tmp_path) == sorted([long, "results/train/A-to-B/L5/seed0/metrics.json"])


def test_killed_forced_rerun_is_redone(tmp_path):
    """`snakemake -f` killed mid-job: outputs gone, report up to date; a plain run redoes the job"""
    (tmp_path / "Snakefile").write_text(textwrap.dedent(f"""
        import sys; sys.path.insert(0, {str(REPO_ROOT / 'src')!r})
        from palpation.killed_jobs import killed_outputs
        rule all:
            input: "report.txt", killed_outputs()
        rule report:
            input: "run/metrics.json"
            output: "report.txt"
            shell: "cp {{input}} {{output}}"
        rule train:
            output: "run/metrics.json", "run/checkpoint.pt"
            shell: "touch {{output}}"
        """))
    (tmp_path / "report.txt").write_text("{}")  # the report of the earlier, complete run
    for out in ("run/metrics.json", "run/checkpoint.pt"):  # what the killed `-f` run left: marks only
        mark(tmp_path, out)
    plan = subprocess.run([sys.executable, "-m", "snakemake", "-n", "--cores", "1", "--rerun-incomplete"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert plan.returncode == 0, plan.stderr
    assert "rule train:" in plan.stdout + plan.stderr and "rule report:" in plan.stdout + plan.stderr

"""workflow/scripts/loop_dev_choice.py: the rule that picks the default loop or a changed one on dev runs."""

import json
import subprocess
import sys

from palpation.paths import REPO_ROOT

SCRIPT = REPO_ROOT / "workflow" / "scripts" / "loop_dev_choice.py"


def summary(tmp_path, name, exact, unexplained, clean, seeds=(1, 2), runs=24):
    d = tmp_path / name
    d.mkdir()
    dev = {"runs": runs * len(seeds), "seeds": list(seeds), "in_list_runs": 36, "out_of_list_runs": 12,
           "exact_named": exact / 36, "out_of_list_unexplained": unexplained / 12, "out_of_list_no_extra": clean / 12}
    (d / "selftest_general.json").write_text(json.dumps({"summary": {"dev": dev}}))
    return d


def choice(a, b, *extra):
    out = subprocess.run([sys.executable, str(SCRIPT), str(a), str(b), *extra], capture_output=True, text=True)
    return out.returncode, out.stdout.strip().splitlines()[-1] if out.stdout.strip() else out.stderr.strip()


def test_a_change_needs_more_exact_runs_and_keeps_the_outside_runs(tmp_path):
    a = summary(tmp_path, "a", 24, 11, 9)
    assert choice(a, summary(tmp_path, "b", 26, 10, 8)) == (0, "changed")
    assert choice(a, summary(tmp_path, "c", 24, 12, 12)) == (0, "default")  # no gain in-list
    assert choice(a, summary(tmp_path, "d", 30, 9, 9)) == (0, "default")  # two outside runs lost
    assert choice(a, summary(tmp_path, "e", 25, 11, 9), "--min-gain", "2") == (0, "default")


def test_other_draws_or_a_missing_summary_are_refused(tmp_path):
    a = summary(tmp_path, "a", 24, 11, 9)
    rc, msg = choice(a, summary(tmp_path, "b", 26, 11, 9, seeds=(1,)))
    assert rc != 0 and "other draws" in msg
    rc, msg = choice(a, tmp_path / "nowhere")
    assert rc != 0 and "no dev summary" in msg

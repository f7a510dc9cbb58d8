"""Slot claiming that spreads training jobs over a host's GPUs (palpation.model.gpu_slots)."""

import subprocess
import sys

import pytest

from palpation.model import gpu_slots


@pytest.fixture
def held():
    """The slots this test claims, released afterwards (the module keeps them for the process's life)."""
    yield gpu_slots._HELD
    for f in gpu_slots._HELD:
        f.close()
    gpu_slots._HELD.clear()


def test_jobs_fill_every_card_before_doubling_up(tmp_path, held):
    cards = [gpu_slots.claim_slot(3, tmp_path) for _ in range(7)]
    assert cards == [0, 1, 2, 0, 1, 2, 0]


def test_a_freed_slot_goes_to_the_least_busy_card(tmp_path, held):
    cards = [gpu_slots.claim_slot(2, tmp_path) for _ in range(3)]  # card 0 has two jobs, card 1 one
    assert cards == [0, 1, 0]
    held[1].close()  # the job on card 1 ends
    assert gpu_slots.claim_slot(2, tmp_path) == 1


def test_a_slot_of_a_finished_process_is_free_again(tmp_path, held):
    # another process claims a slot and exits without cleaning up: its flock goes with it
    code = "import sys; from pathlib import Path; from palpation.model.gpu_slots import claim_slot; " \
           "print(claim_slot(2, Path(sys.argv[1])))"
    out = subprocess.run([sys.executable, "-c", code, str(tmp_path)], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "0"
    assert gpu_slots.claim_slot(2, tmp_path) == 0


def test_cpu_and_explicit_cards_are_left_alone(held):
    assert gpu_slots.shared_cuda("cpu") == "cpu"
    assert gpu_slots.shared_cuda("cuda:1") == "cuda:1"
    assert held == []

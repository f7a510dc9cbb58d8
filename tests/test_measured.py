"""The measured-marker-set format: round trip, strict validation, nothing written on failure."""

import json

import numpy as np
import pytest

from palpation.measured import (MeasuredState, load_measured_set, make_measured_set,
                                parse_photo_name, save_measured_set)
from palpation.paths import FLAT_TIP_PHOTOS


def small_set(n_states=3):
    rng = np.random.default_rng(0)
    rest = rng.uniform(700, 1400, (127, 2))
    markers = rest[None] + rng.normal(0, 5, (n_states, 127, 2))
    found = np.ones((n_states, 127), bool)
    found[1, 7] = False
    kinds = ["rest", "press", "twist_x", "slide", "twist_z"]
    states = [MeasuredState(f"s{i}", f"photo{i}.jpg", kinds[i % 5], 2.0 * i,
                            20.0 if kinds[i % 5] == "twist_x" else None) for i in range(n_states)]
    return make_measured_set(markers, found, rest, states, camera={"f_px": 380.0})


def test_round_trip(tmp_path):
    mset = small_set()
    npz, js = save_measured_set(tmp_path / "mine", mset)
    assert npz.name == "mine.npz" and js.name == "mine.json"
    back = load_measured_set(tmp_path / "mine.npz")
    for key in ("markers", "displacement", "rest", "found"):
        np.testing.assert_array_equal(getattr(back, key), getattr(mset, key).astype(getattr(back, key).dtype))
    assert back.markers.dtype == np.float32 and back.found.dtype == bool
    assert back.states == mset.states and back.meta["camera"] == {"f_px": 380.0}
    np.testing.assert_allclose(back.state_markers("s1"), mset.markers[1], atol=1e-3)


@pytest.mark.parametrize("name, trajectory, depth, angle", [
    ("twist_x_press_depth=2_angle=20_slide_length=50_timestamp=2025-08-30-21-34-40.jpg", "twist_x", 2, 20),
    ("twist_z_press_depth=4_angle=90_slide_length=50_timestamp=2025-08-30-21-26-57.jpg", "twist_z", 4, 90),
    ("press_press_depth=0_angle=10_slide_length=50_timestamp=2025-08-30-21-23-00.jpg", "rest", 0, None),
    ("press_press_depth=4_angle=10_slide_length=50_timestamp=2025-08-30-21-23-31.jpg", "press", 4, None),
    ("slide_press_depth=3_angle=10_slide_length=50_timestamp=2025-08-30-21-49-26.png", "slide", 3, None),
    ("sensor_default_state.png", "rest", 0, None),
])
def test_parse_photo_name(name, trajectory, depth, angle):
    assert (FLAT_TIP_PHOTOS / name).exists()
    assert parse_photo_name(name) == {"trajectory": trajectory, "depth_mm": depth, "angle_deg": angle}


def test_parse_photo_name_rejects_unknown():
    with pytest.raises(ValueError, match="wiggle_press"):
        parse_photo_name("wiggle_press_depth=1.jpg")


def _arrays(mset):
    return {k: getattr(mset, k) for k in ("markers", "displacement", "rest", "found")}


def _nan(a):
    a = a["markers"].copy()
    a[0, 3, 1] = np.nan
    return a


def _inf(a):
    a = a["rest"].copy()
    a[5, 0] = np.inf
    return a


# (description, edit of the arrays) -> every one must fail validation
ARRAY_CASES = {
    "extra key": lambda a: {**a, "extra": np.zeros(3)},
    "missing key": lambda a: {k: v for k, v in a.items() if k != "found"},
    "markers not 3-d": lambda a: {**a, "markers": a["markers"][0]},
    "126 markers": lambda a: {**a, "markers": a["markers"][:, :126], "displacement": a["displacement"][:, :126]},
    "rest wrong shape": lambda a: {**a, "rest": a["rest"][:100]},
    "found wrong shape": lambda a: {**a, "found": a["found"][:, :5]},
    "found not bool": lambda a: {**a, "found": a["found"].astype(np.uint8)},
    "markers int": lambda a: {**a, "markers": a["markers"].astype(np.int32)},
    "nan": lambda a: {**a, "markers": _nan(a)},
    "inf": lambda a: {**a, "rest": _inf(a)},
    "displacement != markers - rest": lambda a: {**a, "displacement": a["displacement"] + 1.0},
}


@pytest.mark.parametrize("case", ARRAY_CASES)
def test_bad_arrays_on_load(tmp_path, case):
    save_measured_set(tmp_path / "set", small_set())
    np.savez(tmp_path / "set.npz", **ARRAY_CASES[case](_arrays(small_set())))
    with pytest.raises(ValueError, match="set.npz") as err:
        load_measured_set(tmp_path / "set")
    assert "\n" not in str(err.value)


def _edit_states(meta, fn):
    meta["states"] = fn(meta["states"])
    return meta


META_CASES = {
    "unknown trajectory": lambda m: _edit_states(m, lambda s: [{**s[0], "trajectory": "wiggle"}] + s[1:]),
    "fewer states than npz": lambda m: _edit_states(m, lambda s: s[:-1]),
    "more states than npz": lambda m: _edit_states(m, lambda s: s + [s[0] | {"name": "x"}]),
    "missing field": lambda m: _edit_states(m, lambda s: [{"name": "a"}] + s[1:]),
    "depth not a number": lambda m: _edit_states(m, lambda s: [{**s[0], "depth_mm": "deep"}] + s[1:]),
    "duplicate names": lambda m: _edit_states(m, lambda s: [s[0], {**s[1], "name": s[0]["name"]}] + s[2:]),
    "wrong version": lambda m: {**m, "format_version": 99},
    "not a measured set": lambda m: {**m, "format": "something else"},
    "states not a list": lambda m: {**m, "states": {"a": 1}},
}


@pytest.mark.parametrize("case", META_CASES)
def test_bad_metadata_on_load(tmp_path, case):
    save_measured_set(tmp_path / "set", small_set())
    meta = json.loads((tmp_path / "set.json").read_text())
    (tmp_path / "set.json").write_text(json.dumps(META_CASES[case](meta)))
    with pytest.raises(ValueError, match="set.json") as err:
        load_measured_set(tmp_path / "set")
    assert "\n" not in str(err.value)


def test_bad_json_syntax_and_missing_files(tmp_path):
    save_measured_set(tmp_path / "set", small_set())
    (tmp_path / "set.json").write_text("{not json")
    with pytest.raises(ValueError, match="set.json"):
        load_measured_set(tmp_path / "set")
    (tmp_path / "set.json").unlink()
    with pytest.raises(FileNotFoundError, match="set.json"):
        load_measured_set(tmp_path / "set")
    with pytest.raises(FileNotFoundError, match="other.npz"):
        load_measured_set(tmp_path / "other")


@pytest.mark.parametrize("case", ["126 markers", "nan", "found wrong shape", "displacement != markers - rest"])
def test_invalid_set_is_never_written(tmp_path, case):
    mset = small_set()
    for key, value in ARRAY_CASES[case](_arrays(mset)).items():
        setattr(mset, key, value)
    with pytest.raises(ValueError, match="bad.npz"):
        save_measured_set(tmp_path / "bad", mset)
    assert list(tmp_path.iterdir()) == []


def test_invalid_states_are_never_written(tmp_path):
    mset = small_set()
    mset.states[0] = MeasuredState("a", "a.jpg", "wiggle")
    with pytest.raises(ValueError, match="bad.json"):
        save_measured_set(tmp_path / "bad", mset)
    mset = small_set()
    mset.states.pop()
    with pytest.raises(ValueError, match="lists 2 states but the npz holds 3"):
        save_measured_set(tmp_path / "bad", mset)
    assert list(tmp_path.iterdir()) == []

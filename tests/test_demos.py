"""Tests of pbdkit.data._demonstration: validation, time rescaling, .npz and CSV I/O."""

from __future__ import annotations

import copy
import pickle
import tracemalloc
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pbdkit.data._demonstration import (
    Demonstration,
    check_demonstrations,
    demonstration_from_csv,
    load_demonstrations,
    save_demonstrations,
)


def random_demo(
    rng: np.random.Generator,
    n_samples: int = 50,
    n_joints: int = 4,
    objects: tuple[str, ...] = ("glass", "coaster"),
    gripper: bool = True,
) -> Demonstration:
    t = np.cumsum(rng.uniform(0.01, 0.05, n_samples))
    return Demonstration(
        t=t,
        joints=rng.normal(size=(n_samples, n_joints)),
        objects={k: rng.normal(size=3) for k in objects},
        gripper=(rng.random(n_samples) > 0.5).astype(float) if gripper else None,
    )


# ----------------------------------------------------------------------------- construction
def test_demonstration_fields_are_validated_read_only_copies() -> None:
    rng = np.random.default_rng(0)
    t = np.linspace(0.0, 2.0, 20)
    q = rng.normal(size=(20, 5))
    pos = np.array([0.4, 0.1, 0.2])
    d = Demonstration(t, q, {"glass": pos}, gripper=[True] * 10 + [False] * 10)
    assert d.n_steps == 20 and d.n_joints == 5 and d.object_names == ("glass",)
    assert d.gripper is not None and d.gripper.dtype == np.float64
    np.testing.assert_array_equal(d.gripper[:10], 1.0)
    assert d.duration == pytest.approx(2.0, abs=1e-12)
    with pytest.raises(ValueError, match="read-only"):
        d.joints[0, 0] = 1.0
    with pytest.raises(TypeError):
        d.objects["cup"] = np.zeros(3)  # type: ignore[index]
    # The caller's arrays stay writable and independent.
    q[0, 0] = 99.0
    pos[0] = 99.0
    assert d.joints[0, 0] != 99.0 and d.objects["glass"][0] == pytest.approx(0.4)
    assert "T=20" in repr(d)


def test_a_demonstration_pickles_and_copies_as_its_arrays() -> None:
    # A skill keeps its demonstrations and travels to Dask workers (a read-only mapping does
    # not pickle by itself).
    rng = np.random.default_rng(5)
    pose = np.eye(4)
    pose[:3, :3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    pose[:3, 3] = [0.4, 0.1, 0.2]
    d = random_demo(rng)
    d = Demonstration(d.t, d.joints, {**d.objects, "mug": pose}, d.gripper)
    for back in (pickle.loads(pickle.dumps(d)), copy.deepcopy(d)):
        assert back is not d and back.object_names == ("glass", "coaster", "mug")
        for field in ("t", "joints", "gripper"):
            np.testing.assert_array_equal(getattr(back, field), getattr(d, field))
            assert not getattr(back, field).flags.writeable
        for k in d.objects:
            np.testing.assert_array_equal(back.objects[k], d.objects[k])
        with pytest.raises(TypeError):
            back.objects["cup"] = np.zeros(3)  # type: ignore[index]


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"t": [0.0]}, r"t must have at least 2 samples, got 1"),
        ({"t": [0.0, 1.0, 1.0]}, r"t must be strictly increasing, got t\[1\]=1.0 >= t\[2\]"),
        ({"t": [0.0, 2.0, 1.0]}, r"strictly increasing"),
        ({"t": [[0.0, 1.0, 2.0]]}, r"t must be 1-D, got 2-D"),
        ({"t": [0.0, np.inf, 2.0]}, r"t must be finite"),
        ({"joints": np.zeros((2, 3))}, r"joints must have shape \(3, n\), got \(2, 3\)"),
        ({"joints": np.zeros(3)}, r"joints must be 2-D"),
        ({"joints": [[0.0, np.nan]] * 3}, r"joints must be finite, got 3 NaN"),
        (
            {"objects": {"glass": [0.0, 1.0]}},
            r"objects\['glass'\] must be a position \(3,\).*got an array of shape \(2,\)",
        ),
        ({"objects": {"glass": [0.0, np.nan, 1.0]}}, r"objects\['glass'\] must be finite"),
        ({"objects": {"joint": [0.0, 0.0, 1.0]}}, r"'joint' is reserved"),
        ({"objects": {3: [0.0, 0.0, 1.0]}}, r"keys must be non-empty strings"),
        ({"objects": [1.0, 2.0, 3.0]}, r"objects must be a dict"),
        ({"gripper": [0.0, 1.0]}, r"gripper must have shape \(3,\), got \(2,\)"),
        ({"gripper": ["a", "b", "c"]}, r"gripper must be an array of numbers"),
        (
            {"gripper": [0.0, 1.5, 1.0]},
            r"gripper\[1\] must be within \[0, 1\] \(0 open, 1 closed\), got 1.5",
        ),
        ({"gripper": [-0.25, 0.0, 2.0]}, r"gripper\[0\] must be within \[0, 1\].*got -0.25"),
    ],
)
def test_demonstration_rejects_bad_input(kwargs: dict[str, object], match: str) -> None:
    args: dict[str, object] = {
        "t": [0.0, 1.0, 2.0],
        "joints": np.zeros((3, 2)),
        "objects": {"glass": [0.1, 0.2, 0.3]},
        "gripper": None,
    }
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        Demonstration(**args)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (
            {"joints": np.ones((3, 2), dtype=complex)},
            r"joints must be an array of numbers, got complex",
        ),
        ({"joints": [["0.1", "0.2"]] * 3}, r"joints must be an array of numbers, got strings"),
        (
            {"joints": np.ones((3, 2), dtype=bool)},
            r"joints must be an array of numbers, got booleans",
        ),
        ({"t": [False, True, 2.0 + 0j]}, r"t must be an array of numbers, got complex"),
        ({"t": np.array([0, 1, 1], dtype=bool)}, r"t must be an array of numbers, got booleans"),
        ({"gripper": np.array([0, 1, 1], dtype=complex)}, r"gripper .* got complex"),
    ],
)
def test_demonstration_refuses_values_that_are_not_real(
    kwargs: dict[str, object], match: str
) -> None:
    """Issue 22: joints of strings, complex (imaginary part dropped) or bool were accepted."""
    args: dict[str, object] = {"t": [0.0, 1.0, 2.0], "joints": np.zeros((3, 2))}
    with pytest.raises(ValueError, match=match):
        Demonstration(**{**args, **kwargs})  # type: ignore[arg-type]
    # A gripper signal may be given as booleans (closed = True).
    d = Demonstration(args["t"], args["joints"], gripper=[False, True, True])  # type: ignore[arg-type]
    assert d.gripper is not None and d.gripper.tolist() == [0.0, 1.0, 1.0]


@pytest.mark.parametrize("dtype", ["<U20", np.complex128, np.bool_])
def test_load_refuses_joints_stored_as_strings_complex_or_bool(tmp_path: Path, dtype: Any) -> None:
    rng = np.random.default_rng(14)
    path = tmp_path / "d.npz"
    save_demonstrations([random_demo(rng), random_demo(rng)], path)
    arrays = _stored(path)
    arrays["demo_1_joints"] = arrays["demo_1_joints"].astype(dtype)
    np.savez(path, **arrays)
    with pytest.raises(
        ValueError, match=r"d\.npz is not a valid pbdkit-demonstrations file: demo_1: joints must"
    ):
        load_demonstrations(path)


# ----------------------------------------------------------------------------- rescaling
def test_rescaled_is_exact_on_linear_signals_and_keeps_endpoints() -> None:
    rng = np.random.default_rng(1)
    t = np.sort(rng.uniform(0.0, 3.0, 40))
    slope, offset = rng.normal(size=3), rng.normal(size=3)
    q = offset + t[:, None] * slope
    g = 0.2 * t
    d = Demonstration(t, q, {"o": [0.0, 0.0, 0.5]}, gripper=g).rescaled(101)
    grid = np.linspace(t[0], t[-1], 101)
    np.testing.assert_array_equal(d.t, np.arange(101.0))
    np.testing.assert_allclose(d.joints, offset + grid[:, None] * slope, rtol=0, atol=1e-12)
    assert d.gripper is not None
    np.testing.assert_allclose(d.gripper, 0.2 * grid, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(d.joints[[0, -1]], q[[0, -1]])
    np.testing.assert_array_equal(d.objects["o"], [0.0, 0.0, 0.5])


def test_rescaled_matches_np_interp_per_joint() -> None:
    rng = np.random.default_rng(2)
    d = random_demo(rng, n_samples=37, n_joints=3)
    r = d.rescaled(64)
    grid = np.linspace(d.t[0], d.t[-1], 64)
    for i in range(3):
        np.testing.assert_allclose(r.joints[:, i], np.interp(grid, d.t, d.joints[:, i]), atol=1e-12)


def test_rescaled_rejects_bad_n_steps() -> None:
    d = random_demo(np.random.default_rng(3))
    with pytest.raises(ValueError, match="n_steps must be >= 2, got 1"):
        d.rescaled(1)
    with pytest.raises(ValueError, match="n_steps must be an integer"):
        d.rescaled(10.5)  # type: ignore[arg-type]


# ----------------------------------------------------------------------------- demo sets
def test_check_demonstrations_rejects_inconsistent_sets() -> None:
    rng = np.random.default_rng(4)
    a = random_demo(rng)
    with pytest.raises(ValueError, match="at least 2 demonstrations, got 1"):
        check_demonstrations([a])
    with pytest.raises(ValueError, match="demos must be a list of Demonstration"):
        check_demonstrations(a)
    with pytest.raises(ValueError, match=r"demos\[1\] must be a Demonstration, got dict"):
        check_demonstrations([a, {}])
    with pytest.raises(ValueError, match=r"demos\[1\] has 3 joints, expected 4"):
        check_demonstrations([a, random_demo(rng, n_joints=3)])
    with pytest.raises(ValueError, match=r"demos\[1\] has objects \['glass'\], expected"):
        check_demonstrations([a, random_demo(rng, objects=("glass",))])
    with pytest.raises(ValueError, match=r"demos\[1\] has no gripper signal"):
        check_demonstrations([a, random_demo(rng, gripper=False)])
    # Same names in another order are the same set.
    b = Demonstration(a.t, a.joints, {"coaster": [0, 0, 1], "glass": [1, 0, 0]}, a.gripper)
    assert len(check_demonstrations([a, b])) == 2


# ----------------------------------------------------------------------------- .npz I/O
@pytest.mark.parametrize("gripper", [True, False])
def test_save_load_round_trip_is_exact(tmp_path: Path, gripper: bool) -> None:
    rng = np.random.default_rng(5)
    demos = [random_demo(rng, n_samples=n, gripper=gripper) for n in (20, 35, 27)]
    path = tmp_path / "sub" / "demos.npz"
    save_demonstrations(demos, path)
    back = load_demonstrations(path)
    assert len(back) == 3
    for a, b in zip(demos, back, strict=True):
        np.testing.assert_array_equal(a.t, b.t)
        np.testing.assert_array_equal(a.joints, b.joints)
        assert a.object_names == b.object_names
        for k in a.objects:
            np.testing.assert_array_equal(a.objects[k], b.objects[k])
        if gripper:
            assert a.gripper is not None and b.gripper is not None
            np.testing.assert_array_equal(a.gripper, b.gripper)
        else:
            assert b.gripper is None
    # No temporary file is left behind, and the file needs no pickle.
    assert [p.name for p in path.parent.iterdir()] == ["demos.npz"]
    with np.load(path, allow_pickle=False) as data:
        assert str(data["format"]) == "pbdkit-demonstrations" and int(data["version"]) == 1


def test_save_load_without_objects(tmp_path: Path) -> None:
    rng = np.random.default_rng(6)
    demos = [random_demo(rng, objects=()) for _ in range(2)]
    save_demonstrations(demos, tmp_path / "d.npz")
    back = load_demonstrations(tmp_path / "d.npz")
    assert back[0].object_names == ()


def test_save_rejects_invalid_sets_and_writes_nothing(tmp_path: Path) -> None:
    rng = np.random.default_rng(7)
    with pytest.raises(ValueError, match="at least 1 demonstrations, got 0"):
        save_demonstrations([], tmp_path / "d.npz")
    with pytest.raises(ValueError, match="has 3 joints"):
        save_demonstrations([random_demo(rng), random_demo(rng, n_joints=3)], tmp_path / "d.npz")
    assert not (tmp_path / "d.npz").exists()


def test_load_rejects_missing_corrupt_foreign_and_other_versions(tmp_path: Path) -> None:
    rng = np.random.default_rng(8)
    with pytest.raises(FileNotFoundError, match="not found"):
        load_demonstrations(tmp_path / "nope.npz")
    bad = tmp_path / "corrupt.npz"
    bad.write_bytes(rng.bytes(200))
    with pytest.raises(ValueError, match=r"corrupt\.npz is not a NumPy \.npz archive"):
        load_demonstrations(bad)
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, x=np.zeros(3))
    with pytest.raises(ValueError, match="is not a pbdkit-demonstrations file"):
        load_demonstrations(foreign)
    path = tmp_path / "d.npz"
    save_demonstrations([random_demo(rng), random_demo(rng)], path)
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    np.savez(tmp_path / "v3.npz", **{**arrays, "version": np.array(3)})
    with pytest.raises(ValueError, match="of version 3; this pbdkit reads version 1 or 2"):
        load_demonstrations(tmp_path / "v3.npz")
    np.savez(tmp_path / "missing.npz", **{k: v for k, v in arrays.items() if k != "demo_1_t"})
    with pytest.raises(ValueError, match="missing key 'demo_1_t'"):
        load_demonstrations(tmp_path / "missing.npz")
    broken = dict(arrays, demo_0_joints=np.full_like(arrays["demo_0_joints"], np.nan))
    np.savez(tmp_path / "nan.npz", **broken)
    with pytest.raises(ValueError, match="joints must be finite"):
        load_demonstrations(tmp_path / "nan.npz")
    # An archive whose member needs pickle is refused without running it.
    pickled = tmp_path / "pickled.npz"
    np.savez(pickled, format=np.array("pbdkit-demonstrations"), obj=np.array([{}], dtype=object))
    with pytest.raises(ValueError, match="pbdkit-demonstrations"):
        load_demonstrations(pickled)
    assert zipfile.is_zipfile(path)


def _stored(path: Path) -> dict[str, np.ndarray]:
    with np.load(path) as data:
        return {k: data[k] for k in data.files}


def _more_joints(a: dict[str, np.ndarray]) -> None:
    a["demo_1_joints"] = np.hstack([a["demo_1_joints"], a["demo_1_joints"][:, :1]])


def _one_more_demo(a: dict[str, np.ndarray]) -> None:
    for key in [k for k in a if k.startswith("demo_1_")]:
        a[key.replace("demo_1_", "demo_2_")] = a[key]


def _duplicate_names(a: dict[str, np.ndarray]) -> None:
    a["object_names"] = np.array(["glass", "glass"])


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (_more_joints, r"demo_1_joints has 5 joints, expected 4 like demo_0_joints"),
        (lambda a: a.update(n_demos=np.array(-1)), r"n_demos must be an integer >= 1, got -1"),
        (lambda a: a.update(n_demos=np.array(0)), r"n_demos must be an integer >= 1, got 0"),
        (lambda a: a.update(n_demos=np.array(2.5)), r"n_demos must be an integer >= 1, got 2.5"),
        (lambda a: a.update(n_demos=np.array(3)), r"missing key 'demo_2_t' \(n_demos is 3\)"),
        (lambda a: a.update(n_demos=np.array(1)), r"n_demos is 1 but the file holds 'demo_1_"),
        (_one_more_demo, r"n_demos is 2 but the file holds 'demo_2_"),
        (lambda a: a.update(has_gripper=np.array([1, 0])), r"has_gripper must be a boolean"),
        (_duplicate_names, r"object_names must be distinct, got \['glass', 'glass'\]"),
    ],
)
def test_load_rejects_inconsistent_files(tmp_path: Path, change: object, match: str) -> None:
    rng = np.random.default_rng(11)
    path = tmp_path / "d.npz"
    save_demonstrations([random_demo(rng), random_demo(rng)], path)
    arrays = _stored(path)
    change(arrays)  # type: ignore[operator]
    bad = tmp_path / "bad.npz"
    np.savez(bad, **arrays)
    with pytest.raises(ValueError, match=r"bad\.npz is not a valid pbdkit-demonstrations file: "):
        load_demonstrations(bad)
    with pytest.raises(ValueError, match=match):
        load_demonstrations(bad)


def test_load_rejects_truncated_archive(tmp_path: Path) -> None:
    rng = np.random.default_rng(10)
    path = tmp_path / "d.npz"
    save_demonstrations([random_demo(rng), random_demo(rng)], path)
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(path.read_bytes()[:100])
    with pytest.raises(ValueError, match=r"not a readable \.npz archive"):
        load_demonstrations(truncated)


def test_load_refuses_unknown_keys_before_loading_any_array(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    rng = np.random.default_rng(12)
    path = tmp_path / "d.npz"
    save_demonstrations([random_demo(rng), random_demo(rng)], path)
    arrays = _stored(path)
    bad = tmp_path / "bad.npz"
    np.savez(bad, **arrays, extra=np.zeros(10**5), demo_01_t=np.zeros(2))
    loaded: list[tuple[int, ...]] = []
    real = np.lib.format.read_array

    def spy(fp: Any, *args: Any, **kwargs: Any) -> np.ndarray:
        out = real(fp, *args, **kwargs)
        loaded.append(out.shape)
        return out

    monkeypatch.setattr(np.lib.format, "read_array", spy)
    with pytest.raises(
        ValueError, match=r"bad\.npz .*: n_demos is 2 but the file holds 'extra', 'demo_01_t',"
    ):
        load_demonstrations(bad)
    assert (10**5,) not in loaded and len(loaded) == 5  # the header keys only


def test_load_bounds_the_work_of_a_huge_n_demos(tmp_path: Path) -> None:
    """n_demos = 10**6 declared, 2 stored: refused at the first missing key, in little memory
    (the check used to list every key n_demos implies)."""
    rng = np.random.default_rng(13)
    path = tmp_path / "d.npz"
    save_demonstrations([random_demo(rng), random_demo(rng)], path)
    bad = tmp_path / "bad.npz"
    np.savez(bad, **{**_stored(path), "n_demos": np.array(10**6)})
    tracemalloc.start()
    try:
        with pytest.raises(ValueError, match=r"missing key 'demo_2_t' \(n_demos is 1000000\)"):
            load_demonstrations(bad)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 2 * 2**20


# ----------------------------------------------------------------------------- CSV
def test_csv_import(tmp_path: Path) -> None:
    rng = np.random.default_rng(9)
    t = np.linspace(0.0, 1.0, 11)
    q = rng.normal(size=(11, 3))
    g = (t > 0.5).astype(float)
    lines = ["# logged on the arm", "t,pan,lift1,lift2,gripper"]
    lines += [",".join(f"{v:.17g}" for v in (t[i], *q[i], g[i])) for i in range(11)]
    path = tmp_path / "demo.csv"
    path.write_text("\n".join(lines) + "\n")
    d = demonstration_from_csv(path, objects={"glass": [0.4, 0.1, 0.1]})
    np.testing.assert_array_equal(d.t, t)
    np.testing.assert_array_equal(d.joints, q)
    assert d.gripper is not None
    np.testing.assert_array_equal(d.gripper, g)
    d2 = demonstration_from_csv(path, objects={}, joint_columns=["lift2", "pan"])
    np.testing.assert_array_equal(d2.joints, q[:, [2, 0]])


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("", "empty CSV file"),
        ("pan,lift1\n0,1\n", "must contain a column 't'"),
        ("t,pan,pan\n0,1,2\n", "duplicate column names"),
        ("t,gripper\n0,1\n1,0\n", "no joint column"),
        ("t,pan\n0,abc\n", "non-numeric or ragged"),
        ("t,pan\n0,1,2\n1,2,3\n", "expected rows of 2 values"),
        ("t,pan\n1,1\n0,2\n", "strictly increasing"),
        ("t,pan\n0,1\n1,nan\n", "joints must be finite"),
    ],
)
def test_csv_rejects_bad_files(tmp_path: Path, text: str, match: str) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(ValueError, match=match):
        demonstration_from_csv(path, objects={})


def test_csv_missing_file_and_columns(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="CSV file not found"):
        demonstration_from_csv(tmp_path / "none.csv", objects={})
    path = tmp_path / "d.csv"
    path.write_text("t,pan\n0,1\n1,2\n")
    with pytest.raises(ValueError, match=r"joint columns \['lift1'\] not in the header"):
        demonstration_from_csv(path, objects={}, joint_columns=["lift1"])
    with pytest.raises(ValueError, match=r"objects\['glass'\] must be a position \(3,\)"):
        demonstration_from_csv(path, objects={"glass": [1.0]})
    binary = tmp_path / "b.csv"
    binary.write_bytes(b"\xff\xfe\x00\x81")
    with pytest.raises(ValueError, match="not a UTF-8 text CSV file"):
        demonstration_from_csv(binary, objects={})


def test_csv_with_a_byte_order_mark_and_other_delimiters(tmp_path: Path) -> None:
    """Issue 22: a UTF-8 BOM (spreadsheets write one) made the first column name '\\ufefft'."""
    path = tmp_path / "bom.csv"
    path.write_bytes(b"\xef\xbb\xbft;pan;lift1\r\n0;0.1;0.2\r\n0.5;0.2;0.3\r\n")
    d = demonstration_from_csv(path, None, delimiter=";")
    np.testing.assert_array_equal(d.t, [0.0, 0.5])
    np.testing.assert_array_equal(d.joints, [[0.1, 0.2], [0.2, 0.3]])
    assert d.object_names == ()
    tabs = tmp_path / "tabs.tsv"
    tabs.write_text("t\tpan\n0\t1\n1\t2\n")
    assert demonstration_from_csv(tabs, {}, delimiter="\t").joints.tolist() == [[1.0], [2.0]]


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (
            {"delimiter": ""},
            r"delimiter must be one character that cannot occur in a number.*got ''",
        ),
        ({"delimiter": ",,"}, r"delimiter must be one character .*got ',,'"),
        ({"delimiter": "."}, r"delimiter must be one character .*got '\.'"),
        ({"delimiter": None}, r"delimiter must be one character .*got None"),
        (
            {"joint_columns": ["pan", "pan"]},
            r"joint_columns must name each column once, got \['pan'\]",
        ),
        ({"joint_columns": ["pan", "t"]}, r"joint_columns: 't' is the time, not a joint"),
        ({"joint_columns": ["gripper"]}, r"joint_columns: 'gripper' is the gripper signal"),
        ({"joint_columns": "pan"}, r"joint_columns must be a list of column names, got str"),
        ({"joint_columns": [0]}, r"joint_columns must be column names \(strings\), got 0"),
        ({"objects": [("glass", [0.0, 0.0, 0.0])]}, r"d\.csv: objects must be a dict"),
    ],
)
def test_csv_refuses_bad_arguments(tmp_path: Path, kwargs: dict[str, Any], match: str) -> None:
    """Issue 22: delimiter="" or objects=None raised TypeError; a column could be used twice."""
    path = tmp_path / "d.csv"
    path.write_text("t,pan,lift1,gripper\n0,1,2,0\n1,2,3,1\n")
    args: dict[str, Any] = {"objects": {}, **kwargs}
    with pytest.raises(ValueError, match=match):
        demonstration_from_csv(path, **args)


def test_csv_errors_from_the_demonstration_name_the_file(tmp_path: Path) -> None:
    path = tmp_path / "log_3.csv"
    path.write_text("t,pan\n0,1\n0,2\n")
    with pytest.raises(ValueError, match=r"log_3\.csv: t must be strictly increasing"):
        demonstration_from_csv(path, {})
    path.write_text("t,pan\n0,1\n1,2\n")
    with pytest.raises(ValueError, match=r"log_3\.csv: objects\['glass'\] must be a position"):
        demonstration_from_csv(path, {"glass": [0.0, 1.0]})

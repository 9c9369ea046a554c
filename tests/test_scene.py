"""Scenes: the shapes, their poses, scene files and their refusals (issue 38, item 2)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import pbdkit
from pbdkit._rotations import matrix_from_quaternion
from pbdkit.collision import Box, Cylinder, Scene, Sphere
from pbdkit.collision._shapes import MAX_SCENE_BYTES


def _one_line(info: pytest.ExceptionInfo[BaseException]) -> str:
    message = str(info.value)
    assert "\n" not in message, message
    return message


def test_the_public_names_are_the_collision_packages() -> None:
    assert pbdkit.Scene is Scene and pbdkit.Box is Box
    assert pbdkit.Sphere is Sphere and pbdkit.Cylinder is Cylinder


@pytest.mark.parametrize(
    ("pose", "position"),
    [
        ((0.1, 0.2, 0.3), (0.1, 0.2, 0.3)),
        ((0.1, 0.2, 0.3, 2.0, 0.0, 0.0, 0.0), (0.1, 0.2, 0.3)),  # normalized
        (np.eye(4), (0.0, 0.0, 0.0)),
    ],
)
def test_a_pose_is_a_position_a_transform_or_a_quaternion_pose(
    pose: object, position: tuple[float, ...]
) -> None:
    box = Box((0.1, 0.2, 0.3), pose)
    assert box.pose.shape == (4, 4)
    np.testing.assert_allclose(box.pose[:3, 3], position)
    np.testing.assert_allclose(box.pose[:3, :3], np.eye(3), atol=1e-15)
    assert not box.pose.flags.writeable


def test_a_quaternion_pose_is_the_rotation_of_that_quaternion() -> None:
    rng = np.random.default_rng(3)
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    cyl = Cylinder(0.02, 0.3, (1.0, 2.0, 3.0, *q))
    np.testing.assert_allclose(cyl.pose[:3, :3], matrix_from_quaternion(q), atol=1e-12)


def test_unnamed_shapes_get_their_kind_and_index() -> None:
    scene = Scene([Box((1, 1, 1)), Sphere(0.1, name="ball"), Cylinder(0.1, 0.2)])
    assert scene.names == ["box_0", "ball", "cylinder_2"]
    assert len(scene) == 3 and list(scene)[1].name == "ball"


def test_a_scene_file_round_trips(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    q = rng.normal(size=4)
    scene = Scene(
        [
            Box((1.2, 0.8, 0.04), (0.3, 0.0, -0.02), name="table"),
            Sphere(0.05, (0.4, 0.1, 0.3, *q)),
            Cylinder(0.03, 0.4, (0.5, 0.3, 0.2)),
        ],
        objects={"glass": Cylinder(0.035, 0.1, (0.0, 0.0, 0.05))},
    )
    path = tmp_path / "scene.yaml"
    scene.save(path)
    back = Scene.load(path)
    assert back.names == scene.names and sorted(back.objects) == ["glass"]
    for a, b in zip(scene.shapes, back.shapes, strict=True):
        assert type(a) is type(b)
        np.testing.assert_allclose(a.pose, b.pose, atol=1e-12)
    assert isinstance(back.shapes[0], Box)
    np.testing.assert_array_equal(back.shapes[0].size, [1.2, 0.8, 0.04])
    assert back.objects["glass"].name == "glass"


def test_the_issues_yaml_form_loads(tmp_path: Path) -> None:
    path = tmp_path / "scene.yaml"
    path.write_text(
        "shapes:\n"
        "  - {type: box, name: shelf, size: [0.2, 0.3, 0.02], pose: [0.5, 0.2, 0.1, 1, 0, 0, 0]}\n"
        "  - {type: sphere, radius: 0.05, pose: [0.3, 0, 0.3]}\n"
        "  - {type: cylinder, name: post, radius: 0.02, length: 0.5,\n"
        "     pose: [0.6, -0.2, 0.25, 0.7071068, 0.7071068, 0, 0]}\n",
        encoding="utf-8",
    )
    scene = Scene.load(path)
    assert scene.names == ["shelf", "sphere_1", "post"]
    post = scene.shapes[2]
    assert isinstance(post, Cylinder) and post.length == 0.5
    # A quarter turn about x: the cylinder's axis (its z) lies along -y.
    np.testing.assert_allclose(post.pose[:3, 2], [0.0, -1.0, 0.0], atol=1e-6)


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: Box((0.1, -0.2, 0.3)), "box size must be > 0"),
        (lambda: Box((0.1, 0.2)), "box size must be 3 side lengths"),
        (lambda: Box(("a", 1, 1)), "box size must be 3 side lengths"),
        (lambda: Sphere(0.0), "sphere radius must be > 0"),
        (lambda: Sphere(float("nan")), "sphere radius must be > 0"),
        (lambda: Sphere(True), "sphere radius must be a number"),
        (lambda: Cylinder(0.1, 1e9), "cylinder length must be > 0 and at most"),
        (lambda: Box((1, 1, 1), (0.0, float("nan"), 0.0)), "box pose must be finite"),
        (lambda: Box((1, 1, 1), (0, 0, 0, 0, 0, 0, 0)), "zero norm"),
        (lambda: Box((1, 1, 1), (0, 0)), "box pose must be a position"),
        (lambda: Sphere(0.1, name=""), "sphere name must be a non-empty string"),
        (lambda: Scene([Box((1, 1, 1), name="a"), Sphere(1, name="a")]), "names must be unique"),
        (lambda: Scene(Box((1, 1, 1))), "shapes must be a list"),
        (lambda: Scene([object()]), r"shapes\[0\] must be a Box"),
        (lambda: Scene([Sphere(1, name="glass")], objects={"glass": Sphere(1)}), "also the name"),
    ],
)
def test_bad_shapes_are_refused_in_one_line(make: object, match: str) -> None:
    with pytest.raises(ValueError, match=match) as info:
        make()  # type: ignore[operator]
    _one_line(info)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("shapes:\n  - {type: cone, radius: 1}\n", r"shapes\[0\]: type must be one of"),
        ("shapes:\n  - {type: box, size: [1, -1, 1]}\n", r"shapes\[0\]: box size must be > 0"),
        ("shapes:\n  - {type: sphere, radius: -0.1}\n", "sphere radius must be > 0"),
        ("shapes:\n  - {type: sphere}\n", r"shapes\[0\] \(sphere\): missing radius"),
        ("shapes:\n  - {type: sphere, radius: 1, pose: [0, .nan, 0]}\n", "pose must be finite"),
        ("shapes:\n  - {type: sphere, radius: 1, pose: [0, x, 0]}\n", "pose must be a list"),
        ("shapes:\n  - {type: sphere, radius: 1, colour: red}\n", "unknown keys"),
        ("shapes: {a: 1}\n", "'shapes' must be a list"),
        ("obstacles: []\n", "unknown keys"),
        ("- 1\n- 2\n", "expected a mapping"),
        ("shapes: [\n", "is not valid YAML"),
        ("shapes: !!python/object:os.system {}\n", "is not valid YAML"),
        ("objects:\n  glass: {type: sphere, radius: 1, name: x}\n", "unknown keys"),
    ],
)
def test_bad_scene_files_are_refused_naming_the_file_and_entry(
    tmp_path: Path, text: str, match: str
) -> None:
    path = tmp_path / "scene.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ValueError, match=match) as info:
        Scene.load(path)
    message = _one_line(info)
    assert str(path) in message, message


def test_a_missing_or_huge_scene_file_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="does not exist") as info:
        Scene.load(tmp_path / "nope.yaml")
    _one_line(info)
    big = tmp_path / "big.yaml"
    big.write_bytes(b"#" * (MAX_SCENE_BYTES + 1))
    with pytest.raises(ValueError, match="over the cap") as info:
        Scene.load(big)
    _one_line(info)


def test_an_alias_bomb_is_refused_or_bounded(tmp_path: Path) -> None:
    # Nine aliases of nine aliases ...: the shapes list expands, its entries are not shapes.
    lines = ['x0: &x0 ["lol"]']
    lines += [f"x{i}: &x{i} [{', '.join([f'*x{i - 1}'] * 9)}]" for i in range(1, 8)]
    lines.append("shapes: *x7")
    path = tmp_path / "bomb.yaml"
    path.write_text("\n".join(lines), encoding="utf-8")
    with pytest.raises(ValueError, match="unknown keys") as info:
        Scene.load(path)
    message = _one_line(info)
    assert len(message) < 600, message

"""The cases of the hostile-input pass (:mod:`hostile_pass`, issue 36): the issue's 18 defects
and their kin, and the fixtures they tamper with."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from dataclasses import dataclass, field
from pathlib import Path

PY = sys.executable
ROOT = Path(__file__).resolve().parent.parent
URDF = ROOT / "src" / "pbdkit" / "robots" / "katana_6m180.urdf"
KATANA_LIMITS = ROOT / "src" / "pbdkit" / "robots" / "katana_6m180_joint_limits.yaml"
PANDA_LIMITS = ROOT / "src" / "pbdkit" / "robots" / "panda_joint_limits.yaml"
GLASS = "0.45,0.2,0.2"  # a reachable glass position for the synthetic skill
SLOT_OK = [
    "block=0.1458,0.1218,0.0229,0.99873,0,0,0.05044",
    "tray=0.1430,-0.1220,0.0190,0.99795,0,0,-0.0640",
]


@dataclass
class Case:
    item: str  # the item number, or "kin N"
    name: str
    kind: str  # "py": code run in a fresh interpreter; "cli": pbdkit's arguments; "serve"; "sigint"
    body: str | list[str]
    expect: str = "refuse"  # or "accept"
    match: str | None = None  # what the error must say (a substring, case-insensitive)
    seconds: float = 20.0
    mb: float = 800.0
    extra: dict[str, float] = field(default_factory=dict)


# ------------------------------------------------------------------------------------ fixtures
_SETUP = """
import sys, warnings
import numpy as np
warnings.simplefilter("ignore")
sys.path.insert(0, {tests!r})
from synthetic_teacher import synthetic_demos
import pbdkit
from pbdkit.robots import katana
r = katana()
demos = synthetic_demos(r, np.random.default_rng(0))
pbdkit.save_demonstrations(demos, {fix!r} + "/demos.npz")
skill = pbdkit.Skill.learn(demos, r, n_steps=100, random_state=0)
skill.save({fix!r} + "/skill.npz")
from pbdkit.sim._task_skill import teach
slot = teach("slot", 3, seed=0, speed=2.0)
pbdkit.Skill.learn(slot, katana(), n_steps=100, random_state=0).save({fix!r} + "/slot.npz")
"""


def make_fixtures(fix: Path) -> None:
    code = _SETUP.format(tests=str(ROOT / "tests"), fix=str(fix))
    subprocess.run([PY, "-c", code], check=True, cwd=ROOT)
    bomb = ["x0: &x0 [" + ", ".join(['"lol"'] * 9) + "]"]
    for i in range(1, 9):
        bomb.append(f"x{i}: &x{i} [" + ", ".join([f"*x{i - 1}"] * 9) + "]")
    head = "\n".join(bomb) + "\n"
    joint = "pan"
    files = {
        "bomb_value.yaml": head + f"joint_limits:\n  {joint}:\n    has_velocity_limits: true\n"
        "    max_velocity: *x7\n",
        "bomb_entry.yaml": head + f"joint_limits:\n  {joint}: *x8\n",
        "bomb_top.yaml": head + "joint_limits: *x8\n",
        "bomb_flag.yaml": head + f"joint_limits:\n  {joint}:\n    has_velocity_limits: *x8\n",
        "deep.yaml": "joint_limits: " + "[" * 5000 + "]" * 5000 + "\n",
        "deep_map.yaml": "joint_limits: " + "{a: " * 3000 + "1" + "}" * 3000 + "\n",
        "typo.yaml": f"joint_limits:\n  {joint}x:\n    has_acceleration_limits: true\n"
        "    max_acceleration: 2.0\n",
        "tiny_velocity.yaml": f"joint_limits:\n  {joint}:\n    has_velocity_limits: true\n"
        "    max_velocity: 1.0e-300\n",
        "small_velocity.yaml": f"joint_limits:\n  {joint}:\n    has_velocity_limits: true\n"
        "    max_velocity: 1.0e-9\n",
        "tiny_jerk.yaml": f"joint_limits:\n  {joint}:\n    has_jerk_limits: true\n"
        "    max_jerk: 1.0e-300\n",
        "huge_number.yaml": f"joint_limits:\n  {joint}:\n    has_velocity_limits: true\n"
        "    max_velocity: 1" + "0" * 400 + "\n",
        "python_tag.yaml": "joint_limits: !!python/object/apply:os.system ['true']\n",
        "not_yaml.yaml": "joint_limits: [unclosed\n",
        "empty.yaml": "",
    }
    for name, text in files.items():
        (fix / name).write_text(text)
    # 13 MB of valid YAML (a limits file is a few KB).
    rows = "".join(
        f"  j{i}:\n    has_velocity_limits: true\n    max_velocity: 1.0\n" for i in range(260000)
    )
    (fix / "big.yaml").write_text("joint_limits:\n" + rows)
    (fix / "not_a_urdf.urdf").write_text("this is not xml at all\n")
    (fix / "empty.urdf").write_text("<robot name='r'></robot>\n")


# --------------------------------------------------------------------------------------- cases
def _tamper(key: str, expr: str) -> str:
    """Code: the fixture skill with one array replaced (``expr`` of ``v``, the old value)."""
    return textwrap.dedent(f"""
        z = dict(np.load(FIX + "/skill.npz"))
        v = z[{key!r}]
        z[{key!r}] = {expr}
        np.savez(FIX + "/t.npz", **z)
        skill = pbdkit.Skill.load(FIX + "/t.npz")
        res = skill.reproduce({{"glass": np.array([{GLASS}])}})
        assert np.all(np.isfinite(res.joints)), "non-finite joints"
    """)


def _slot_tamper(key: str, expr: str) -> str:
    return textwrap.dedent(f"""
        z = dict(np.load(FIX + "/slot.npz"))
        keys = [k for k in z if k.startswith({key!r})]
        assert keys, sorted(z)
        for k in keys:
            v = z[k]
            z[k] = {expr}
        np.savez(FIX + "/t.npz", **z)
        pbdkit.Skill.load(FIX + "/t.npz")
    """)


def _quat(pose: str, via: str = "reproduce") -> str:
    call = {
        "reproduce": "skill.reproduce({'block': p, 'tray': tray})",
        "controller": "c = skill.controller({'block': [0.1458,0.1218,0.0229,0.99873,0,0,0.05044],"
        " 'tray': tray}); c.step(skill.constraints().joint_mean[0]);"
        " c.step(skill.constraints().joint_mean[0], objects={'block': p});"
        " assert all(np.all(np.isfinite(o)) for o in c.objects.values()), 'NaN stored'",
    }[via]
    return textwrap.dedent(f"""
        skill = pbdkit.Skill.load(FIX + "/slot.npz")
        tray = [0.1430, -0.1220, 0.0190, 0.99795, 0, 0, -0.0640]
        p = np.array({pose}, dtype=float)
        out = {call}
    """)


def _frames(change: str) -> str:
    return textwrap.dedent(f"""
        rng = np.random.default_rng(0)
        t = np.linspace(0.0, 1.0, 50)
        trajs, frames = [], []
        for i in range(3):
            b = rng.normal(size=2)
            trajs.append(np.column_stack([t, np.outer(t, [1.0, 0.5]) + b]))
            frames.append([(np.eye(2), b), (np.eye(2), np.zeros(2))])
        kw = {{"n_components": 3}}
        {change}
        m = pbdkit.FrameModel.learn(trajs, frames, **kw)
        mean, cov = m.reproduce(frames[0], t)
        assert np.all(np.isfinite(mean)) and np.all(np.isfinite(cov)), "non-finite result"
    """)


def cases() -> list[Case]:
    out: list[Case] = []
    add = out.append
    sk, demos, slot = "{FIX}/skill.npz", "{FIX}/demos.npz", "{FIX}/slot.npz"

    # 1. the view's poses (and kin: malformed placements through the CLI)
    add(
        Case(
            "1",
            "view: two valid poses",
            "serve",
            [
                "view",
                "--no-browser",
                "--skill",
                slot,
                "--object",
                SLOT_OK[0],
                "--object",
                SLOT_OK[1],
                "--port",
                "8791",
            ],
            "accept",
            seconds=60,
        )
    )
    for bad, why in [
        ("block=0.1,0.1,0.02,0,0,0,0", "zero quaternion"),
        ("block=0.1,0.1,0.02,nan,0,0,1", "NaN"),
        ("block=0.1,0.1,0.02,1,0,0", "6 numbers"),
        ("block=0.1,0.1", "2 numbers"),
        ("block=a,b,c", "not numbers"),
        ("nothing=0.1,0.1,0.02", "unknown object"),
    ]:
        add(
            Case(
                "1",
                f"view: {why}",
                "serve",
                ["view", "--no-browser", "--skill", slot, "--object", bad, "--object", SLOT_OK[1]],
                match="object",
                seconds=60,
            )
        )
    add(
        Case(
            "kin 1",
            "reproduce: pose of a zero quaternion",
            "cli",
            [
                "reproduce",
                slot,
                "--object",
                "block=0.1,0.1,0.02,0,0,0,0",
                "--object",
                SLOT_OK[1],
                "--out",
                "{FIX}/r.npz",
            ],
            match="quaternion",
        )
    )
    add(
        Case(
            "kin 1",
            "reproduce: two valid poses",
            "cli",
            [
                "reproduce",
                slot,
                "--object",
                SLOT_OK[0],
                "--object",
                SLOT_OK[1],
                "--out",
                "{FIX}/r.npz",
            ],
            "accept",
            seconds=60,
        )
    )

    # 2. alias bombs, and other YAML kin
    for f in ("bomb_value", "bomb_entry", "bomb_top", "bomb_flag"):
        add(
            Case(
                "2",
                f"read_joint_limits: {f}",
                "py",
                f"from pbdkit.robots._joint_limits import read_joint_limits\n"
                f"read_joint_limits(FIX + '/{f}.yaml')",
                match="joint",
                seconds=2,
                mb=400,
            )
        )
    add(
        Case(
            "2",
            "learn --joint-limits: alias bomb",
            "cli",
            [
                "learn",
                demos,
                "--robot",
                str(URDF),
                "--joint-limits",
                "{FIX}/bomb_value.yaml",
                "--out",
                "{FIX}/s.npz",
            ],
            match="max_velocity",
            seconds=10,
            mb=400,
        )
    )
    add(
        Case(
            "kin 2",
            "read_joint_limits: a python tag",
            "py",
            "from pbdkit.robots._joint_limits import read_joint_limits\n"
            "read_joint_limits(FIX + '/python_tag.yaml')",
            match="joint_limits",
        )
    )
    add(
        Case(
            "kin 2",
            "read_joint_limits: not YAML",
            "py",
            "from pbdkit.robots._joint_limits import read_joint_limits\n"
            "read_joint_limits(FIX + '/not_yaml.yaml')",
            match="joint_limits",
        )
    )
    add(
        Case(
            "kin 2",
            "read_joint_limits: empty file",
            "py",
            "from pbdkit.robots._joint_limits import read_joint_limits\n"
            "read_joint_limits(FIX + '/empty.yaml')",
            match="joint_limits",
        )
    )

    # 3. joint names that match nothing
    add(
        Case(
            "3",
            "from_urdf: a typo in a joint name",
            "py",
            f"pbdkit.Robot.from_urdf({str(URDF)!r}, joint_limits=FIX + '/typo.yaml')",
            match="panx",
        )
    )
    add(
        Case(
            "3",
            "from_urdf: the Panda's file on the Katana",
            "py",
            f"pbdkit.Robot.from_urdf({str(URDF)!r}, joint_limits={str(PANDA_LIMITS)!r})",
            match="panda",
        )
    )
    add(
        Case(
            "3",
            "from_urdf: the Katana's own file",
            "py",
            f"r = pbdkit.Robot.from_urdf({str(URDF)!r}, joint_limits={str(KATANA_LIMITS)!r})\n"
            "assert np.all(np.isfinite(r.jerk_limit))",
            "accept",
        )
    )
    add(
        Case(
            "3",
            "learn --joint-limits: a typo",
            "cli",
            [
                "learn",
                demos,
                "--robot",
                str(URDF),
                "--joint-limits",
                "{FIX}/typo.yaml",
                "--out",
                "{FIX}/s.npz",
            ],
            match="panx",
        )
    )

    # 4. fine grids
    for n in (20000, 60000):
        add(
            Case(
                "4",
                f"learn n_steps={n}, then reproduce",
                "py",
                textwrap.dedent(f"""
            demos = pbdkit.load_demonstrations(FIX + "/demos.npz")
            s = pbdkit.Skill.learn(demos, katana(), n_steps={n}, random_state=0)
            res = s.reproduce({{"glass": np.array([{GLASS}])}})
            assert np.all(np.isfinite(res.joints))
            # Timed, not crawling: 2.2x the demonstrations' pace at 1000 steps; 70x and 203x
            # at 20000 and 60000 steps before issue 36 (the taper crept along the path).
            assert res.stretch < 30, f"slowed {{res.stretch:.0f}}x"
        """),
                "accept-or-refuse",
                match="n_steps",
                seconds=120,
                mb=3000,
            )
        )
    add(
        Case(
            "4",
            "learn n_steps=10**6",
            "py",
            textwrap.dedent("""
        demos = pbdkit.load_demonstrations(FIX + "/demos.npz")
        s = pbdkit.Skill.learn(demos, katana(), n_steps=10**6, random_state=0)
        s.reproduce({"glass": np.array([0.45, 0.2, 0.2])})
    """),
            "accept-or-refuse",
            match="n_steps",
            seconds=120,
            mb=6000,  # 1e6 steps of a fused reproduction: about 4.5 GB, linear in the steps
        )
    )
    add(
        Case(
            "kin 4",
            "learn --n-steps 0",
            "cli",
            ["learn", demos, "--n-steps", "0", "--out", "{FIX}/s.npz"],
            match="n_steps",
        )
    )
    add(
        Case(
            "kin 4",
            "learn --n-steps 10**9",
            "cli",
            ["learn", demos, "--n-steps", "1000000000", "--out", "{FIX}/s.npz"],
            match="n_steps",
            seconds=20,
        )
    )

    # 5. huge quaternions (and 4x4 kin)
    for pose, expect in [
        ("[0.1458,0.1218,0.0229,1e200,0,0,0]", "accept"),
        ("[0.1458,0.1218,0.0229,1e308,1e308,0,0]", "accept"),
        ("[0.1458,0.1218,0.0229,1e-200,0,0,0]", "accept-or-refuse"),
        ("[0.1458,0.1218,0.0229,np.inf,0,0,0]", "refuse"),
        ("[0.1458,0.1218,0.0229,1e200,1e200,1e200,1e200]", "accept"),
    ]:
        q = "(" + ",".join(pose.strip("[]").split(",")[3:]) + ")"
        add(
            Case(
                "5",
                f"reproduce: quaternion {q}",
                "py",
                _quat(pose),
                expect,
                match="block",
                seconds=60,
            )
        )
        add(
            Case(
                "5",
                f"ctrl.step: quaternion {q}",
                "py",
                _quat(pose, "controller"),
                expect,
                match="block",
                seconds=60,
            )
        )
    add(
        Case(
            "kin 5",
            "reproduce: a 4x4 of 1e200",
            "py",
            _quat("np.full((4, 4), 1e200)"),
            match="block",
            seconds=60,
        )
    )
    add(
        Case(
            "kin 5",
            "reproduce: a 4x4 that reflects",
            "py",
            _quat("np.diag([1.0, 1.0, -1.0, 1.0])"),
            match="block",
            seconds=60,
        )
    )
    add(
        Case(
            "kin 5",
            "reproduce --object block=...,1e200,0,0,0 (CLI)",
            "cli",
            [
                "reproduce",
                slot,
                "--object",
                "block=0.1458,0.1218,0.0229,1e200,0,0,0",
                "--object",
                SLOT_OK[1],
                "--out",
                "{FIX}/r.npz",
            ],
            "accept",
            seconds=60,
        )
    )

    # 6. --trials
    for n in ("1000000000", "0", "-3"):
        add(
            Case(
                "6",
                f"evaluate --trials {n}",
                "cli",
                ["evaluate", "--task", "coaster", "--trials", n, "--json", "{FIX}/e.json"],
                match="trials",
                seconds=20,
                mb=600,
            )
        )

    # 7. SIGINT at start-up: the view ends at any moment of it
    for delay in (0.3, 0.8, 1.5, 2.5, 4.0):
        add(
            Case(
                "7",
                f"view: SIGINT {delay} s after start",
                "sigint",
                [
                    "view",
                    "--no-browser",
                    "--skill",
                    sk,
                    "--object",
                    f"glass={GLASS}",
                    "--port",
                    str(8800 + round(10 * delay)),
                ],
                "accept",
                seconds=10,
                extra={"delay": delay},
            )
        )

    # 8. a file that cannot be read back
    add(
        Case(
            "8",
            "save_demonstrations over the load cap",
            "py",
            textwrap.dedent("""
        import pbdkit._io as io
        demos = pbdkit.load_demonstrations(FIX + "/demos.npz")
        io.MAX_NPZ_BYTES = 10_000  # the cap, made small: what load refuses, save refuses
        try:
            pbdkit.save_demonstrations(demos, FIX + "/big.npz")
        finally:
            import os
            assert not os.path.exists(FIX + "/big.npz"), "a file was written"
    """),
            match="bytes",
        )
    )

    # 9. extreme limits
    for kw in (
        "velocity_limit=1e-300",
        "velocity_limit=1e-9",
        "acceleration_limit=1e-300",
        "jerk_limit=1e-300",
        "jerk_limit=1e-9",
        "velocity_limit=1e300",
    ):
        add(
            Case(
                "9",
                f"reproduce({kw})",
                "py",
                textwrap.dedent(f"""
            skill = pbdkit.Skill.load(FIX + "/skill.npz")
            skill.reproduce({{"glass": np.array([{GLASS}])}}, {kw})
        """),
                match=kw.split("=")[0].split("_")[0],
                seconds=30,
            )
        )
    for f in ("tiny_velocity", "small_velocity", "tiny_jerk"):
        add(
            Case(
                "9",
                f"learn --joint-limits {f}",
                "cli",
                [
                    "learn",
                    demos,
                    "--robot",
                    str(URDF),
                    "--joint-limits",
                    f"{{FIX}}/{f}.yaml",
                    "--out",
                    "{FIX}/s.npz",
                ],
                match="max_",
                seconds=30,
            )
        )

    # 10. the view's --robot
    for why, given in [
        ("not a URDF", "{FIX}/not_a_urdf.urdf"),
        ("an empty URDF", "{FIX}/empty.urdf"),
        ("panda with a Katana skill", "panda"),
        ("a missing file", "{FIX}/nothing.urdf"),
    ]:
        view = ["view", "--no-browser", "--skill", sk, "--robot", given]
        add(Case("10", f"view --robot: {why}", "serve", view, match="robot", seconds=30))

    # 11. a skill file's duration
    for expr in (
        "np.float64(1e300)",
        "np.float64(-1.0)",
        "np.float64(np.nan)",
        "np.float64(0.0)",
        "np.float64(np.inf)",
    ):
        add(
            Case(
                "11",
                f"skill file: duration {expr[11:-1]}",
                "py",
                _tamper("duration", expr),
                "accept-or-refuse" if "nan" in expr else "refuse",  # NaN: unknown, documented
                match="duration",
            )
        )
    add(
        Case(
            "11",
            "reproduce --out of a skill of duration 1e300",
            "py",
            _tamper("duration", "np.float64(1e300)") + "res.save(FIX + '/r.npz')",
            match="duration",
        )
    )

    # 12. FrameModel
    tiny = (
        "trajs = [np.column_stack([x[:, 0], x[:, 1:] * 1e-300]) for x in trajs]\n"
        "        frames = [[(np.eye(2), b * 1e-300) for _, b in f] for f in frames]"
    )
    for why, change, expect, match in [
        ("A = 1e-200 I", "frames[1][0] = (1e-200 * np.eye(2), frames[1][0][1])", "refuse", "frame"),
        ("A = 1e200 I", "frames[1][0] = (1e200 * np.eye(2), frames[1][0][1])", "refuse", "frame"),
        ("times of 1e300", "trajs[0][:, 0] = trajs[0][:, 0] * 1e300", "refuse", "traject"),
        ("points of 1e300", "trajs[0][:, 1:] = trajs[0][:, 1:] * 1e300", "refuse", "traject"),
        ("points of 1e-300", tiny, "accept-or-refuse", "traject"),
        ("random_state='x'", "kw['random_state'] = 'x'", "refuse", "random_state"),
        ("random_state=-1", "kw['random_state'] = -1", "refuse", "random_state"),
    ]:
        add(Case("12", f"FrameModel: {why}", "py", _frames(change), expect, match=match))
    tampered = textwrap.dedent("""
        m.save(FIX + "/fm.npz")
        z = dict(np.load(FIX + "/fm.npz"))
        for k in z:
            if "means" in k:
                z[k] = np.full_like(z[k], 1e308)
        np.savez(FIX + "/fm2.npz", **z)
        m2 = pbdkit.FrameModel.load(FIX + "/fm2.npz")
        mean, cov = m2.reproduce(frames[0], t)
        assert np.all(np.isfinite(mean)), "non-finite result"
    """)
    add(Case("12", "FrameModel: a tampered file, means 1e308", "py", _frames("") + tampered,
             match="means"))  # fmt: skip

    # 13, 14: deep and big YAML
    for f in ("deep", "deep_map"):
        add(
            Case(
                "13",
                f"read_joint_limits: {f}",
                "py",
                "from pbdkit.robots._joint_limits import read_joint_limits\n"
                f"read_joint_limits(FIX + '/{f}.yaml')",
                match="joint_limits",
                seconds=5,
            )
        )
    add(
        Case(
            "14",
            "read_joint_limits: 13 MB",
            "py",
            "from pbdkit.robots._joint_limits import read_joint_limits\n"
            "read_joint_limits(FIX + '/big.yaml')",
            match="cap",
            seconds=5,
            mb=400,
        )
    )

    # 15. complex arrays in a skill file
    add(
        Case(
            "15",
            "slot skill file: complex rot_base",
            "py",
            _slot_tamper("rot_base", "v.astype(complex) + 1j"),
            match="rot_base",
        )
    )
    add(
        Case(
            "kin 15",
            "skill file: complex means",
            "py",
            _tamper("gmm_joint_means", "v.astype(complex)"),
            match="gmm_joint_means",
        )
    )

    # 16. 10**400 through the mapping form
    add(
        Case(
            "16",
            "from_urdf(joint_limits={...: 10**400})",
            "py",
            f"pbdkit.Robot.from_urdf({str(URDF)!r}, joint_limits={{'joint_limits': "
            "{'pan': {'has_velocity_limits': True, "
            "'max_velocity': 10**400}}})",
            match="max_velocity",
        )
    )
    add(
        Case(
            "16",
            "learn --joint-limits: 10**400 in the file",
            "cli",
            [
                "learn",
                demos,
                "--robot",
                str(URDF),
                "--joint-limits",
                "{FIX}/huge_number.yaml",
                "--out",
                "{FIX}/s.npz",
            ],
            match="max_velocity",
        )
    )

    # 17. K at load
    add(
        Case(
            "17",
            "skill file with K = 100000",
            "py",
            textwrap.dedent("""
        z = dict(np.load(FIX + "/skill.npz"))
        d = z["gmm_joint_means"].shape[1]
        K = 100000
        z["gmm_joint_weights"] = np.full(K, 1.0 / K)
        z["gmm_joint_means"] = np.zeros((K, d))
        z["gmm_joint_covariances"] = np.broadcast_to(np.eye(d), (K, d, d)).copy()
        np.savez(FIX + "/t.npz", **z)
        skill = pbdkit.Skill.load(FIX + "/t.npz")
        skill.reproduce({"glass": np.array([0.45, 0.2, 0.2])})
    """),
            match="component",
            seconds=30,
            mb=1500,
        )
    )

    # 18. NaN where a result is written
    add(
        Case(
            "18",
            "ReproductionResult.save with a NaN joint",
            "py",
            textwrap.dedent(f"""
        skill = pbdkit.Skill.load(FIX + "/skill.npz")
        res = skill.reproduce({{"glass": np.array([{GLASS}])}})
        res.joints[3, 1] = np.nan
        try:
            res.save(FIX + "/nan.npz")
        finally:
            import os
            assert not os.path.exists(FIX + "/nan.npz"), "a file was written"
    """),
            match="joints",
        )
    )
    # kin: other inputs of the same entry points
    glass = "pbdkit.Skill.load(FIX + '/skill.npz').reproduce({'glass': %s})"
    for value, why in [("[np.nan, 0.2, 0.2]", "NaN"), ("[1e400, 0.2, 0.2]", "inf"),
                       ("[0.45, 0.2]", "2 numbers"), ("'glass'", "a string")]:  # fmt: skip
        add(Case("kin 5", f"reproduce: glass {why}", "py", glass % value, match="glass"))
    add(Case("kin 4", "learn --max-components 100000", "cli",
             ["learn", demos, "--max-components", "100000", "--out", "{FIX}/s.npz"],
             match="max_components"))  # fmt: skip
    add(Case("kin 11", "Skill.load: a truncated file", "py", textwrap.dedent("""
        data = open(FIX + "/skill.npz", "rb").read()
        open(FIX + "/cut.npz", "wb").write(data[: len(data) // 2])
        pbdkit.Skill.load(FIX + "/cut.npz")
    """), match="cut.npz"))  # fmt: skip
    add(Case("kin 8", "load_demonstrations: not an npz", "py", textwrap.dedent("""
        open(FIX + "/x.npz", "w").write("hello")
        pbdkit.load_demonstrations(FIX + "/x.npz")
    """), match="x.npz"))  # fmt: skip
    add(Case("kin 18", "write_trajectory_bag: a NaN joint", "py", textwrap.dedent("""
        t = np.linspace(0.0, 1.0, 11)
        q = np.zeros((11, 2))
        q[4, 1] = np.nan
        pbdkit.write_trajectory_bag(FIX + "/bag", t, q, ["a", "b"])
    """), match="joints"))  # fmt: skip
    return out

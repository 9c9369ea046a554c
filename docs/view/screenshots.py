"""The README's screenshots of ``pbdkit view``, taken in headless Chromium (Debian's chromium,
software WebGL): the coaster task after a physics run, the slot task with its tray turned, and
a Panda skill file (a URDF without meshes: the stick figure through its links).

Run: ``MUJOCO_GL=egl .venv/bin/python docs/view/screenshots.py`` (about a minute); writes
``docs/view/*.png``.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pbdkit
from pbdkit.apps._view import ViewApp
from pbdkit.apps._view_plan import typical_placements
from pbdkit.apps._view_serve import HOST, served
from pbdkit.sim._task_skill import learn_task
from pbdkit.sim._tasks import yaw_pose

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent.parent / "tests"))
from browser import free_port, launch  # noqa: E402
from pose_teacher import demonstrations  # noqa: E402

# The notice headless Chromium gets about software WebGL is not what a user sees.
HIDE_NOTICE = ".mantine-Notification-root { display: none !important; }"


def shoot(
    browser: Any, factory: Callable[[Any], ViewApp], path: Path, act: Callable[[ViewApp], None]
) -> None:
    port = free_port()
    with served(factory, port=port) as app:
        app.wait_idle(60)
        page = browser.new_page(viewport={"width": 1400, "height": 860})
        page.goto(f"http://{HOST}:{port}")
        page.wait_for_selector("canvas", timeout=60_000)
        page.add_style_tag(content=HIDE_NOTICE)
        act(app)
        app.wait_idle(60)
        time.sleep(3.0)
        page.screenshot(path=str(path))
        page.close()
    print(f"wrote {path}")


def main() -> None:
    from playwright.sync_api import sync_playwright

    coaster = learn_task("coaster", n_demos=5, seed=0)
    slot = learn_task("slot", n_demos=5, seed=0)
    panda = pbdkit.robots.panda()
    mug = pbdkit.Skill.learn(demonstrations(panda, seed=0), panda)

    def coaster_run(app: ViewApp) -> None:
        glass = app.objects["glass"].copy()
        glass[:2] += [-0.02, 0.03]
        app.move_object("glass", glass)
        app.wait_idle(60)
        app.start_run(online=False).join()

    def slot_turn(app: ViewApp) -> None:
        tray = app.objects["tray"]
        app.move_object("tray", yaw_pose(tray[:3, 3], math.radians(-45.0)))
        app.wait_idle(60)
        app.ui_step.value = int(0.7 * app.ui_step.max)  # the block over the pocket

    with sync_playwright() as p:
        browser = launch(p)
        try:
            shoot(
                browser,
                lambda s: ViewApp(
                    coaster.skill,
                    coaster.task.nominal_objects(),
                    s,
                    task_skill=coaster,
                    title="task coaster",
                ),
                HERE / "coaster.png",
                coaster_run,
            )
            shoot(
                browser,
                lambda s: ViewApp(
                    slot.skill, slot.task.nominal_objects(), s, task_skill=slot, title="task slot"
                ),
                HERE / "slot.png",
                slot_turn,
            )
            shoot(
                browser,
                lambda s: ViewApp(mug, typical_placements(mug), s, title="skill mug.npz (Panda)"),
                HERE / "panda.png",
                lambda app: None,
            )
        finally:
            browser.close()


if __name__ == "__main__":
    main()

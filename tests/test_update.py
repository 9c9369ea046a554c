"""Learning one more demonstration (issue 39, item 4): ``Skill.update`` against a refit, and
Calinon & Billard's direct update against the M-step it stands for."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic_teacher import N_STEPS, bare_skill, synthetic_demos

from pbdkit import Skill
from pbdkit.data._demonstration import Demonstration
from pbdkit.prob import GMM
from pbdkit.prob._em import MAX_TIME_SPREAD, MIN_TIME_SPREAD, _Floor, _params_from_stats
from pbdkit.prob._incremental import direct_update
from pbdkit.robots._robot import Robot
from pbdkit.skill._encoding import RESELECT_GROWTH


@pytest.fixture(scope="module")
def more(robot: Robot) -> list[Demonstration]:
    """Five more demonstrations of the conftest's task (another seed)."""
    return synthetic_demos(robot, np.random.default_rng(7))


def _tightest_hand(skill: Skill, objects: dict[str, np.ndarray]) -> np.ndarray:
    """The hand at the step where the glass constraint is tightest, on the skill's grid."""
    cov = skill.constraints().task_cov["glass"][:, :3, :3]
    k = int(np.argmin(np.linalg.eigvalsh(cov)[:, -1]))
    res = skill.reproduce(objects)
    own = ~res.lead_in
    return np.array([np.interp(k, res.t[own], res.positions[own][:, i]) for i in range(3)])


def test_an_update_keeps_k_and_reproduces_as_a_refit(
    skill: Skill, demos: list[Demonstration], more: list[Demonstration]
) -> None:
    # One more demonstration: K is kept (chosen with 5), each EM starts from the old fit,
    # and the hand where the glass constraint is tightest is where a refit puts it (1 mm).
    updated = skill.update(more[0])
    refit = Skill.learn([*demos, more[0]], skill.robot, n_steps=N_STEPS, random_state=0)
    assert updated.n_components_ == skill.n_components_
    for k, gmm in updated.gmms.items():
        assert gmm.selection_ is skill.gmms[k].selection_  # K as it was chosen
        assert gmm.selection_.n_folds == 5
        assert not np.array_equal(gmm.means_, skill.gmms[k].means_)  # learned the new one
    assert updated.demonstrations_ is not None and len(updated.demonstrations_) == 6
    assert updated.demonstrations_[-1] is more[0] or np.array_equal(
        updated.demonstrations_[-1].t, more[0].t
    )
    assert updated.n_samples_ == {k: v * 6 // 5 for k, v in (skill.n_samples_ or {}).items()}
    rng = np.random.default_rng(0)
    for _ in range(3):
        glass = np.mean([d.objects["glass"] for d in demos], axis=0)
        objects = {"glass": glass + np.r_[rng.uniform(-0.03, 0.03, 2), 0.0]}
        apart = np.linalg.norm(_tightest_hand(updated, objects) - _tightest_hand(refit, objects))
        assert apart < 1e-3


def test_k_is_chosen_again_once_the_demonstrations_have_doubled(
    skill: Skill, demos: list[Demonstration], more: list[Demonstration]
) -> None:
    # 5 + 5 >= RESELECT_GROWTH x 5: every space chooses K again, as a refit does (to the bit:
    # the positions-only skill keeps no orientation base that could differ).
    assert RESELECT_GROWTH * 5 <= 10
    updated = skill.update(more)
    refit = Skill.learn([*demos, *more], skill.robot, n_steps=N_STEPS, random_state=0)
    assert updated.n_components_ == refit.n_components_
    for k, gmm in updated.gmms.items():
        assert gmm.selection_.n_folds == 10
        np.testing.assert_array_equal(gmm.means_, refit.gmms[k].means_)
        np.testing.assert_array_equal(gmm.covariances_, refit.gmms[k].covariances_)
    np.testing.assert_array_equal(updated.calibration_["joint"], refit.calibration_["joint"])


def test_an_update_refuses_what_it_cannot_learn(
    skill: Skill, demos: list[Demonstration], robot: Robot
) -> None:
    bare = bare_skill(skill)
    with pytest.raises(ValueError, match=r"re-learn it with Skill.learn to use update") as info:
        bare.update(demos[0])
    assert "\n" not in str(info.value)
    with pytest.raises(ValueError, match=r"at least one"):
        skill.update([])
    with pytest.raises(ValueError, match=r"Demonstration or a sequence"):
        skill.update("demo.npz")  # type: ignore[arg-type]
    other = Demonstration(
        t=demos[0].t,
        joints=demos[0].joints,
        objects={"cup": demos[0].objects["glass"]},
        gripper=demos[0].gripper,
    )
    with pytest.raises(ValueError, match=r"does not match the skill's demonstrations") as info:
        skill.update(other)
    assert "\n" not in str(info.value)


def test_the_direct_update_is_the_m_step_of_the_old_and_new_statistics() -> None:
    # Calinon & Billard's direct update, one EM iteration: the old model is the M-step of its
    # N_old rows under responsibilities R; its statistics (N_old pi_k, mu_k, Sigma_k less the
    # floor) stand for those rows. The updated model must be the M-step of the old rows under
    # R and the new rows under the old model's responsibilities, summed by brute force.
    rng = np.random.default_rng(5)
    t = np.tile(np.arange(100.0), 4)
    x_old = np.c_[t, np.sin(t / 15.0) + rng.normal(0, 0.1, t.size), rng.normal(0, 0.3, t.size)]
    k = 3
    resp_old = rng.dirichlet(np.ones(k), size=t.size)
    diag = np.array([1e-6, 1e-3, 2e-3])
    span = float(np.ptp(t))
    floor = _Floor(diag, 0, MIN_TIME_SPREAD * span, MAX_TIME_SPREAD * span)

    def m_step(x: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        s0 = r.sum(axis=0)
        s1 = r.T @ x
        s2 = np.einsum("nk,ni,nj->kij", r, x, x)
        return _params_from_stats(s0, s1, s2, floor)

    old = GMM.from_params(*m_step(x_old, resp_old))
    tn = np.arange(100.0)
    x_new = np.c_[tn, np.cos(tn / 20.0), rng.normal(0, 0.3, tn.size)]
    updated = direct_update(old, x_new, t.size, reg_covar=diag, max_iter=1)
    h = old.predict_proba(x_new)
    weights, means, cov = m_step(np.r_[x_old, x_new], np.r_[resp_old, h])
    np.testing.assert_allclose(updated.weights_, weights, rtol=1e-9)
    np.testing.assert_allclose(updated.means_, means, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(updated.covariances_, cov, rtol=1e-7, atol=1e-10)
    # More iterations: the new rows' likelihood does not fall.
    longer = direct_update(old, x_new, t.size, reg_covar=diag, max_iter=50)
    assert longer.score(x_new) >= updated.score(x_new) - 1e-9
    with pytest.raises(ValueError, match="columns"):
        direct_update(old, x_new[:, :2], t.size, reg_covar=diag)

"""The two-host-thread CPU path of the physics gives the same bits as one thread.

The per-body and per-character kernels run on the two halves of the crowd (the contacts'
terms too: each half takes the contacts that touch it, in order), the narrow phase on two
ranges of its threads (the second into a scratch buffer appended after the first), the
current and look-ahead targets and capsule poses at once, so the contacts come out in the
same order and every state the same, whatever the split
(``crowdstudy.warp_runtime.run_parallel``)."""

from __future__ import annotations

import numpy as np
import pytest

from crowdstudy.errors import InvalidInputError


@pytest.fixture(scope="module")
def concert():
    from crowdstudy.design import load_design
    from crowdstudy.motion.baseline import build_baseline

    return build_baseline(load_design(), "stationary", "D5", duration=0.3, body_model="open")


def _run(
    anim,
    monkeypatch,
    threads: str,
    steps: int = 8,
    capacity: int | None = None,
    split: float | None = None,
    split_pcg: bool = True,
    config=None,
):
    import crowdstudy.physics.collision as collision
    import crowdstudy.physics.solver as solver
    import crowdstudy.physics.state as state
    from crowdstudy.physics.collision import Contacts
    from crowdstudy.physics.corrector import CrowdCorrector, load_bodies

    monkeypatch.setenv("CROWDSTUDY_THREADS", threads)
    monkeypatch.setattr(collision, "_MIN_SPLIT_THREADS", 0)  # split even this small scene
    monkeypatch.setattr(solver, "_MIN_CHARACTERS_PER_THREAD", 1)
    monkeypatch.setattr(solver, "_MIN_CHARACTERS_SPLIT_PCG", 1 if split_pcg else 10**9)  # the split PCG too
    monkeypatch.setattr(solver, "_MIN_CHARACTERS_SPLIT_ASSEMBLY", 1)  # the contacts' terms by halves
    monkeypatch.setattr(collision, "_MIN_CHARACTERS_PARALLEL", 1)  # the three capsule poses at once
    monkeypatch.setattr(state, "_MIN_CHARACTERS_PARALLEL", 1)  # the two targets at once
    corr = CrowdCorrector(load_bodies(anim.bodies), fps=anim.fps, n_frames=anim.n_frames, device="cpu", config=config)
    if capacity is not None:
        corr.contacts = Contacts.allocate(capacity, "cpu")
    if split is not None:
        corr.pipeline._split = split
        corr.pipeline._balance = lambda *a: None  # keep this split
    corr.control.set_frames(anim.joint_rotations, anim.root_translation)
    corr.reset_to_frame(0)
    contacts = []
    for s in range(steps):
        f = 1 + s // corr.substeps
        corr.control.advance(f - 1, f, (s % corr.substeps + 1) / corr.substeps)
        corr.pipeline.collide(corr.states[0], corr.contacts, corr.control)
        contacts.append((int(corr.contacts.count.numpy()[0]), corr.contacts.to_numpy()))
        corr.solver.step(corr.states[0], corr.states[1], corr.control, corr.contacts, corr.dt)
        corr.states.reverse()
    return corr.states[0].numpy(), contacts


def _same(a, b):
    (state_a, contacts_a), (state_b, contacts_b) = a, b
    for key in ("x", "q", "v", "w"):
        np.testing.assert_array_equal(state_a[key], state_b[key])
    for (na, ca), (nb, cb) in zip(contacts_a, contacts_b, strict=True):
        assert na == nb
        for key in ca:
            np.testing.assert_array_equal(ca[key], cb[key])


@pytest.mark.parametrize("split", [None, 0.1, 0.9])
def test_two_host_threads_give_the_same_bits(concert, monkeypatch, split):
    one = _run(concert, monkeypatch, "1")
    two = _run(concert, monkeypatch, "2", split=split)
    assert max(n for n, _ in one[1]) > 100  # the scene has contacts (inter-body among them)
    assert any((c["kind"] == 2).any() for _, c in one[1])
    _same(one, two)


def test_the_split_pcg_solves_what_the_fused_one_solves(concert, monkeypatch):
    # the PCG split over the two halves of the crowd (per-half rows and contacts, the partial
    # dot products added in a fixed order) differs from the one-launch PCG only in the
    # summation order of its dot products: solved tightly, both reach the same states
    from crowdstudy.physics.config import PhysicsConfig

    tight = PhysicsConfig().with_values(cg_tolerance=1e-6, cg_max_iterations=400)
    fused = _run(concert, monkeypatch, "1", split_pcg=False, config=tight)
    split = _run(concert, monkeypatch, "2", split_pcg=True, config=tight)
    assert any((c["kind"] == 2).any() for _, c in fused[1])
    assert not np.array_equal(split[0]["x"], fused[0]["x"])  # not the same code path ...
    np.testing.assert_allclose(split[0]["x"], fused[0]["x"], rtol=0, atol=5e-5)  # ... the same solution (m; float32 CG)
    np.testing.assert_allclose(split[0]["v"], fused[0]["v"], rtol=0, atol=5e-3)  # m/s


def test_overflowing_contacts_drop_the_same_surplus(concert, monkeypatch):
    # a capacity below the contacts found: both paths keep the first `capacity` in the same
    # order and report the same (overflowing) count
    one = _run(concert, monkeypatch, "1", steps=3, capacity=300)
    two = _run(concert, monkeypatch, "2", steps=3, capacity=300, split=0.5)
    assert one[1][-1][0] > 300
    _same(one, two)


def test_host_threads_setting(monkeypatch):
    from crowdstudy.warp_runtime import host_threads, run_parallel

    monkeypatch.setenv("CROWDSTUDY_THREADS", "1")
    assert host_threads() == 1
    monkeypatch.setenv("CROWDSTUDY_THREADS", "2")
    assert host_threads() == 2
    out = []
    t0, t1 = run_parallel(lambda: out.append("a"), lambda: out.append("b"))
    assert sorted(out) == ["a", "b"] and t0 >= 0 and t1 >= 0
    with pytest.raises(ZeroDivisionError):  # an error on the helper thread reaches the caller
        run_parallel(lambda: None, lambda: 1 / 0)
    monkeypatch.setenv("CROWDSTUDY_THREADS", "two")
    with pytest.raises(InvalidInputError, match="CROWDSTUDY_THREADS"):
        host_threads()


def test_run_together_meets_at_a_barrier_or_declines(monkeypatch):
    """``run_together`` runs two callables that wait for each other on two threads at once,
    or (one host thread) runs nothing and says so; an error on either side reaches the
    caller without leaving the other side waiting."""
    import threading

    from crowdstudy.warp_runtime import run_together

    monkeypatch.setenv("CROWDSTUDY_THREADS", "1")
    ran = []
    assert run_together(lambda: ran.append(1), lambda: ran.append(2)) is False and ran == []
    monkeypatch.setenv("CROWDSTUDY_THREADS", "2")
    barrier = threading.Barrier(2, timeout=10)
    seen = []

    def side(name):
        for step in range(3):
            seen.append((step, name))
            barrier.wait()

    assert run_together(lambda: side("a"), lambda: side("b")) is True
    assert [s for s, _ in seen] == [0, 0, 1, 1, 2, 2]  # in step with each other

    broken = threading.Barrier(2, timeout=10)

    def fails():
        broken.abort()
        raise ZeroDivisionError

    def waits():
        with pytest.raises(threading.BrokenBarrierError):
            broken.wait()

    with pytest.raises(ZeroDivisionError):
        run_together(waits, fails)


def test_device_names_are_cpu_cuda_or_cuda_n():
    from crowdstudy.physics.solver import LINEAR_SOLVERS, PRECONDITIONERS
    from crowdstudy.warp_runtime import device_kind, resolve_device

    assert [device_kind(d) for d in ("cpu", "cuda", "cuda:0", "cuda:12")] == ["cpu", "cuda", "cuda", "cuda"]
    for bad in ("gpu", "cpu:0", "cuda:", "CUDA", "", None):
        with pytest.raises(InvalidInputError, match="device: expected 'cpu', 'cuda' or 'cuda:N'"):
            device_kind(bad)
    with pytest.raises(InvalidInputError, match="device"):
        resolve_device("gpu0")
    assert resolve_device("cpu") == "cpu"
    assert LINEAR_SOLVERS == ("fused", "warp", "scipy") and PRECONDITIONERS == ("character", "body")

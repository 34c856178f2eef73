"""``crowdstudy bench preconditioners``: would a stronger preconditioner make the PCG cheaper?

The solver's PCG (``crowdstudy.physics.solver``) preconditions with one exact block per
character (its bodies and joints, a tree). Contacts that stiffen with their depth couple the
characters, which that block does not see, so the iterations grow with the depth of a dense tiled D5
crowd. This benchmark takes the very systems the solver assembles (``Solver.triplets``
after ``--warmup`` steps of the tiled D5 concert) and solves each with numpy PCG to the
solver's relative tolerance under:

* ``character``: the solver's own preconditioner (exact per-character blocks; its iterations
  should equal the fused PCG's, which the table shows beside it);
* ``+translation``: plus an additive coarse correction on every character's translation
  (3 unknowns a character, solved exactly);
* ``+rigid``: the same with every character's rigid motion (6 unknowns: translation and a
  rotation about its mean body position);
* ``rigid two-level``: coarse, then the character blocks on the coarse residual, then coarse
  again (symmetric multiplicative: two more products with the matrix per application);
* ``block SGS``: symmetric block Gauss-Seidel over the characters (a forward and a backward
  sweep; the character blocks solved exactly, the couplings between characters applied in
  sweep order).

Iterations alone flatter the stronger preconditioners, so the table counts the work of a
solve in products with the whole matrix (``matvec``), character-block solves (``block``) and
couplings applied outside a sweep's block (``coupling``, in matvec-equivalents: the
inter-character share of the matrix's entries), and adds them into ``cost``: matvecs +
block solves (a tree solve costs about one product in the fused kernel) + couplings; the
coarse solves (3,000-6,000 unknowns) are left out in its favour. Lower ``cost`` than
``character`` would be a faster solve. This is a study of iteration counts on the CPU in
numpy, not a timing.
"""

from __future__ import annotations

import argparse

import numpy as np

__all__ = ["main", "sample_systems", "compare"]


def sample_systems(n_characters: int, warmup: int, samples: tuple[int, ...]):
    """Run the corrector's steps on the tiled D5 concert and keep the assembled system at
    the steps ``samples`` (< ``warmup``): a list of {step, A (CSR), tree (A without the
    contacts' couplings), b, x (body positions), fused_iterations, tolerance (the solver's
    relative residual), contacts}, the number of bodies and the joints per character."""
    from crowdstudy.design import load_design
    from crowdstudy.motion.baseline import build_baseline
    from crowdstudy.physics.linear import bsr_from_triplets
    from crowdstudy.physics.step_timing import tile_crowd, timed_corrector

    base = build_baseline(load_design(), "stationary", "D5", duration=warmup / 60.0 + 0.5)
    anim = base if n_characters == base.n_characters else tile_crowd(base, n_characters)
    corr = timed_corrector(anim)
    nb, nj = corr.model.n_bodies, corr.model.n_joints
    sub, out = corr.substeps, []
    for s in range(warmup):
        f = 1 + (s // sub) % (anim.n_frames - 1)
        corr.control.advance(f - 1, f, ((s % sub) + 1) / sub)
        corr.pipeline.collide(corr.states[0], corr.contacts, corr.control)
        corr.solver.assemble(corr.states[0], corr.control, corr.contacts, corr.dt)
        corr.solver.solve(corr.contacts)
        if s in samples:
            rows, cols, vals, rhs = (a.numpy().copy() for a in corr.solver.triplets(corr.contacts))
            vals = vals.astype(np.float64)
            a = bsr_from_triplets(rows, cols, vals, nb).tocsr()
            # the first 3B triplets: each body's diagonal block and its joint's couplings
            tree = bsr_from_triplets(rows[: 3 * nb], cols[: 3 * nb], vals[: 3 * nb], nb).tocsr()
            out.append(
                {
                    "step": s,
                    "A": a,
                    "tree": tree,
                    "b": rhs.astype(np.float64).ravel(),
                    "x": corr.states[0].x.numpy().astype(np.float64),
                    "fused_iterations": corr.solver.last_cg[0],
                    "tolerance": float(corr.config.solver.cg_tolerance),
                    "contacts": int(corr.contacts.n_active()),
                }
            )
        corr.solver.update(corr.states[0], corr.states[1], corr.dt)
        corr.states.reverse()
    return out, nb, nj


def _pcg(a, b, apply_m, tol: float, max_iter: int) -> int:
    """Iterations of PCG from zero until |r| <= tol |b| (the solver's criterion)."""
    r = b.copy()
    z = apply_m(r)
    p, rz, limit = z.copy(), float(r @ z), tol * np.linalg.norm(b)
    for k in range(1, max_iter + 1):
        q = a @ p
        r -= (rz / float(p @ q)) * q  # the iterate itself is not needed, only its residual
        if np.linalg.norm(r) <= limit:
            return k
        z = apply_m(r)
        rz_new = float(r @ z)
        p = z + (rz_new / rz) * p
        rz = rz_new
    return max_iter


def _rigid_basis(x: np.ndarray, nj: int, rotations: bool):
    """(6B, 3C or 6C) map from each character's translation (and rotation about its mean
    body position) to its bodies' [dx; dw]."""
    import scipy.sparse as sp

    nb = len(x)
    body = np.arange(nb)
    char = body // nj
    k = 6 if rotations else 3
    rows = [6 * body[:, None] + np.arange(3)]
    cols = [k * char[:, None] + np.arange(3)]
    vals = [np.ones((nb, 3))]
    if rotations:
        centre = x.reshape(-1, nj, 3).mean(axis=1)[char]
        d = x - centre
        rows.append(6 * body[:, None] + 3 + np.arange(3))  # dw = w
        cols.append(6 * char[:, None] + 3 + np.arange(3))
        vals.append(np.ones((nb, 3)))
        # dx += w x d = -[d]x w
        skew = np.zeros((nb, 3, 3))
        skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = d[:, 2], -d[:, 1], d[:, 0]
        skew[:, 1, 0], skew[:, 2, 0], skew[:, 2, 1] = -d[:, 2], d[:, 1], -d[:, 0]
        rows.append(np.repeat(6 * body[:, None] + np.arange(3), 3, axis=1))
        cols.append(np.tile(6 * char[:, None] + 3 + np.arange(3), 3))
        vals.append(skew.reshape(nb, 9))
    shape = (6 * nb, k * (nb // nj))
    return sp.csr_matrix(
        (
            np.concatenate([v.ravel() for v in vals]),
            (np.concatenate([r.ravel() for r in rows]), np.concatenate([c.ravel() for c in cols])),
        ),
        shape=shape,
    )


def compare(system: dict, nb: int, nj: int, tol: float | None = None, max_iter: int = 400) -> list[dict]:
    """One row per preconditioner for one assembled system (see the module docstring);
    ``tol``: relative residual (None: the solver's, ``system["tolerance"]``)."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spl

    a, b = system["A"], system["b"]
    tol = system["tolerance"] if tol is None else tol
    size, nc = 6 * nj, nb // nj
    owner = np.arange(6 * nb) // size
    coo = a.tocoo()
    between = owner[coo.row] != owner[coo.col]
    coupling_share = float(between.sum()) / a.nnz
    # the solver's blocks: bodies and joints only (the first 3B triplets), exactly inverted;
    # everything else (contacts between bodies, within a character or between two) is coupling
    blocks = [system["tree"][c * size : (c + 1) * size, c * size : (c + 1) * size].toarray() for c in range(nc)]
    tri = sp.block_diag(blocks, format="csr")
    inv = [np.linalg.inv(blk) for blk in blocks]
    inv_all = sp.block_diag(inv, format="csr")
    count = {"matvec": 0, "block": 0, "coupling": 0.0}

    def blocks_solve(r):
        count["block"] += 1
        return inv_all @ r

    def coarse(basis):
        lu = spl.splu((basis.T @ a @ basis).tocsc())
        return lambda r: basis @ lu.solve(basis.T @ r)

    trans, rigid = coarse(_rigid_basis(system["x"], nj, False)), coarse(_rigid_basis(system["x"], nj, True))

    def two_level(r):
        y = rigid(r)
        count["matvec"] += 2
        y = y + blocks_solve(r - a @ y)
        return y + rigid(r - a @ y)

    off = (a - tri).tocoo()
    lower = sp.csr_matrix(
        (off.data[off.row > off.col], (off.row[off.row > off.col], off.col[off.row > off.col])), shape=a.shape
    )
    upper = sp.csr_matrix(
        (off.data[off.row < off.col], (off.row[off.row < off.col], off.col[off.row < off.col])), shape=a.shape
    )
    lower_rows = [lower[c * size : (c + 1) * size] for c in range(nc)]
    upper_rows = [upper[c * size : (c + 1) * size] for c in range(nc)]

    def sgs(r):
        """(B + U)^-1 B (B + L)^-1 r, B the character blocks, L / U the couplings below / above."""
        y = np.zeros_like(r)
        for c in range(nc):
            s = slice(c * size, (c + 1) * size)
            y[s] = inv[c] @ (r[s] - lower_rows[c] @ y)
        t = tri @ y
        w = np.zeros_like(r)
        for c in range(nc - 1, -1, -1):
            s = slice(c * size, (c + 1) * size)
            w[s] = inv[c] @ (t[s] - upper_rows[c] @ w)
        count["block"] += 2
        count["coupling"] += coupling_share
        return w

    cases = {
        "character": blocks_solve,
        "+translation": lambda r: blocks_solve(r) + trans(r),
        "+rigid": lambda r: blocks_solve(r) + rigid(r),
        "rigid two-level": two_level,
        "block SGS": sgs,
    }
    rows = []
    for name, apply_m in cases.items():
        count.update(matvec=0, block=0, coupling=0.0)
        it = _pcg(a, b, apply_m, tol, max_iter)
        matvecs = count["matvec"] + it
        rows.append(
            {
                "step": system["step"],
                "contacts": system["contacts"],
                "preconditioner": name,
                "iterations": it,
                "fused_iterations": system["fused_iterations"],
                "matvec": matvecs,
                "block": count["block"],
                "coupling": round(count["coupling"], 1),
                "cost": round(matvecs + count["block"] + count["coupling"], 1),
            }
        )
    base = rows[0]["cost"]
    for r in rows:
        r["cost_ratio"] = round(r["cost"] / base, 2)
    return rows


def main(argv: list[str]) -> int:
    from crowdstudy.bench import write_report
    from crowdstudy.tables import format_table

    parser = argparse.ArgumentParser(prog="crowdstudy bench preconditioners", description=__doc__.split("\n")[0])
    parser.add_argument("--characters", type=int, default=1000, help="tiled D5 concert characters (default 1000)")
    parser.add_argument("--warmup", type=int, default=40, help="steps simulated (default 40)")
    parser.add_argument("--samples", default="20,39", help="steps whose systems are compared (default 20,39)")
    args = parser.parse_args(argv)
    try:
        samples = tuple(int(v) for v in args.samples.split(","))
    except ValueError:
        raise SystemExit("--samples: expected comma-separated step numbers") from None
    if args.characters < 1 or not all(0 <= s < args.warmup for s in samples):
        raise SystemExit("--characters must be positive and every --samples step below --warmup")
    systems, nb, nj = sample_systems(args.characters, args.warmup, samples)
    rows = []
    for system in systems:
        rows += compare(system, nb, nj)
    print(format_table(rows), flush=True)
    path = write_report("preconditioners", rows, seed=None, characters=args.characters)
    print(f"report: {path}")
    return 0

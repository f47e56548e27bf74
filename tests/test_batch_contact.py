"""fold_batch with self-contact: problems padded with their contact meshes (the padding inert
to contact) fold as they fold alone, and a problem whose pairs outgrow their room is folded
again alone."""

from __future__ import annotations

import importlib

import jax
import numpy as np
import pytest

from origami_jax import fold, fold_batch, patterns
from origami_jax.contact import Capacity, all_pairs, build_pairs, contact_mesh
from origami_jax.solvers import Status

jax.config.update("jax_enable_x64", True)


def _batch():
    """Full valleys, of two sheet sizes, and a valley held short of flat by its target: one
    size bucket, each member padded (6 vertices to 16)."""
    return [
        patterns.single_crease(fold_angle=np.pi),
        patterns.single_crease(fold_angle=np.pi, width=2.0),
        patterns.single_crease(fold_angle=0.95 * np.pi),
    ]


def _assert_same_fold(batched, alone):
    assert batched.converged, batched.reason
    assert alone.converged, alone.reason
    scale = alone.pattern.diameter
    np.testing.assert_allclose(batched.positions, alone.positions, rtol=0, atol=1e-9 * scale)
    assert batched.contact_dhat == pytest.approx(alone.contact_dhat, rel=1e-12)
    assert batched.contact_kappa == pytest.approx(alone.contact_kappa, rel=1e-12)
    assert batched.contact_pairs == alone.contact_pairs
    assert batched.contact_min_ratio == pytest.approx(alone.contact_min_ratio, rel=1e-6)
    assert len(batched.intersections) == 0 and len(batched.through_pi) == 0


def test_batched_contact_folds_as_each_folds_alone():
    cps = _batch()
    results = fold_batch(cps, contact=True)
    for cp, batched in zip(cps, results, strict=True):
        _assert_same_fold(batched, fold(cp, contact=True, path="direct"))
    # the full valleys stop within the barrier's reach, short of pi, as fold's do
    for r in results[:2]:
        assert r.contact_pairs >= 1 and 0.0 < r.contact_min_ratio <= 1.0
        assert np.pi - 0.01 < np.abs(r.fold_angles).max() < np.pi - 1e-4


def test_a_member_whose_pairs_outgrow_their_room_is_folded_again_alone(monkeypatch):
    # room for a single candidate pair: the sheet's outgrow it at once
    batch_module = importlib.import_module("origami_jax.batch")
    monkeypatch.setattr(batch_module, "contact_capacity", lambda *_: Capacity(1, 1, 1, 1, 1, 1))
    alone = []

    def folded_alone(*args, **kwargs):
        alone.append(fold(*args, **kwargs))
        return alone[-1]

    monkeypatch.setattr(batch_module, "fold", folded_alone)
    cp = patterns.single_crease(fold_angle=np.pi)
    (batched,) = fold_batch([cp], contact=True)
    # the batch's try stopped for want of room; the result is the fold alone, from flat, which
    # grew its room (fold's own contact tests check that fold)
    assert len(alone) == 1 and batched is alone[0]
    assert batched.status == Status.CONVERGED and batched.path == "direct"
    assert batched.contact_pairs >= 1 and 0.0 < batched.contact_min_ratio <= 1.0
    assert len(batched.intersections) == 0 and len(batched.through_pi) == 0


def test_padding_vertices_are_inert_to_contact():
    # a vertex of a negative group (the padding's) is in no pair: with every vertex, triangle
    # and edge of one sheet stacked on another's, only the real ones pair
    cp = patterns.single_crease(fold_angle=0.0)
    mesh = contact_mesh(cp.mesh)
    v = mesh.num_vertices
    x = np.concatenate([cp.mesh.vertices, cp.mesh.vertices + [0.0, 0.0, 1e-4]])
    both = contact_mesh(
        np.concatenate([mesh.triangles, mesh.triangles + v]),
        2 * v,
        groups=np.concatenate([np.arange(v), -np.ones(v, int)]),
    )
    brute = all_pairs(both, x)
    assert len(brute.pt) > 0  # the first sheet's own pairs (vertices against far triangles)
    assert np.all(np.asarray(brute.pt) < v) and np.all(np.asarray(brute.ee) < v)
    alone = all_pairs(mesh, x[:v])
    assert len(brute.pt) == len(alone.pt) and len(brute.ee) == len(alone.ee)
    built = build_pairs(
        x,
        jax.tree.map(np.asarray, both),
        1.0,
        brute.capacity._replace(pt_cells=4096, pt_raw=4096, ee_cells=4096, ee_raw=4096),
    )
    assert not bool(built.did_overflow)
    rows = np.asarray(built.pt)[np.asarray(built.pt_mask)]
    assert len(rows) == len(alone.pt) and np.all(rows < v)
    rows = np.asarray(built.ee)[np.asarray(built.ee_mask)]
    assert len(rows) == len(alone.ee) and np.all(rows < v)


def test_contact_in_a_batch_refuses_what_it_cannot_do():
    cp = patterns.single_crease(fold_angle=np.pi)
    with pytest.raises(ValueError, match="share_topology"):
        fold_batch([cp, cp], contact=True, share_topology=True)
    with pytest.raises(ValueError, match="dhat must be finite"):
        fold_batch([cp], contact=-1.0)

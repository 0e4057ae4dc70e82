"""station design (issue 28): a vertical candidate's own columns are eliminated exactly.

About a vertical axis the table's vibration across the axis is one (P, Q) per table axis, rate,
axis group and mounting (station/model/table_vibration.py): four columns that only that group's
turns see.  information.py eliminates them with the group's nuisances (the search's Schur
complement per axis group) instead of carrying them in the shared block G, which made the
search's matrices grow by four columns per vertical candidate (docs/design.md, sixteenth session:
the size effect's --separate design 52-54 s of CPU).  The elimination must not change what the
design knows: the information about the shared parameters equals the Schur complement of the full
matrix (G with every group's own columns in it, the sixteenth session's information) to 1e-10.
"""
import numpy as np

from station.design import candidates as cm
from station.design import information as inf
from station.design.information import UNIT_DWELL_S, Noise, information, schur
from station.design.search import Candidate, Criterion, Scorer
from station.model.lever_arm import AccelLeverArm
from station.model.table_vibration import TableVibration

# the tolerance: both sides are the same sums of the same candidates' blocks, eliminated in one
# step (the group's axis and vibration columns together) or in two (the axis columns per group,
# then the vibration's from G); Schur complements compose exactly, so only rounding differs.  The
# rounding is relative to what enters the subtraction, the information before any nuisance is
# eliminated (P: the candidates' blocks on G summed), not to the result: a column can keep 1e-7 of
# it (measured here: min diag(R)/P 1e-7, the gyro's columns after the Earth rate and tangent of
# each axis group), so the result carries ~1e-16 x 1e7 = 1e-9 of itself (measured 9.4e-9: the
# module's pinv and a direct solve differ by as much on the level groups, which this change does
# not touch), while relative to P it is ~n eps (measured 1.1e-15).  So the check is
# |F - R|_ij <= 1e-10 sqrt(P_i P_j): 1e5 above the rounding, and leaving a group's own columns
# out instead (their information dropped, not eliminated) misses it by orders of magnitude
TOL = 1e-10


def _chunks():
    """Nine statics and level turns about four axes (chunk 1); vertical turns about three body axes
    at two rates, two lengths at one of them (chunk 2: the two lengths share their group's columns,
    the other rate has its own)."""
    statics = [(("static", u), cm.static_spec(u, UNIT_DWELL_S)) for u in cm.directions()[:9]]
    level, vertical = [], []
    for ax in ((1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0)):
        a = tuple(float(v) / float(np.linalg.norm(ax)) for v in ax)
        level.append(((a, 0.0, 100.0, 1), cm.rotation_pair(a, 0.0, 100.0, 1)))
    for ax in ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)):
        for rate, rev in ((100.0, 1), (100.0, 2), (30.0, 1)):
            vertical.append(((ax, 90.0, rate, rev), cm.rotation_pair(ax, 90.0, rate, rev)))
    cands = [Candidate(k + (UNIT_DWELL_S,), "static", 1.0, dwell_s=UNIT_DWELL_S, slot=k[1]) for k, _ in statics]
    cands += [Candidate(k, "rotation", 1.0, axis=k[:2]) for k, _ in level + vertical]
    return [statics + level, [(("anchor",) + k, s) for k, s in statics] + vertical], cands


def _information(monkeypatch, eliminate: bool, ridge: bool = False):
    """(information, the search's F of every candidate); ``ridge``: with the covariance's ridge
    as the search adds it to a group's own columns (search.complement), not the information itself."""
    from station.design import search

    chunks, cands = _chunks()
    with monkeypatch.context() as m:
        if not eliminate:        # the full matrix: every group's own columns left in G
            m.setattr(inf, "_vertical_own", lambda model, owner: {})
        info = information(chunks, [TableVibration(), AccelLeverArm()], Noise())
        if not ridge:
            m.setattr(search, "RIDGE", 0.0)
        F = Scorer(info, cands, Criterion("D"), np.arange(3)).information(range(len(cands)))
    return info, F


def test_a_vertical_groups_own_columns_are_eliminated_exactly(monkeypatch):
    info, F = _information(monkeypatch, eliminate=True)
    assert not any("_across" in n for n in info.column_names)
    full_info, full = _information(monkeypatch, eliminate=False)
    own = [k for k, n in enumerate(full_info.column_names) if "_across" in n]
    # the vertical groups' own columns: 4 per group and rate (3 body axes x 2 rates), in G before
    assert len(own) == 24
    assert info.shared == full_info.shared - len(own)
    assert not any("_across" in n for n in info.parameters.names)
    # the same shared columns, then the full matrix's Schur complement in its own columns
    where = {n: k for k, n in enumerate(full_info.column_names)}
    keep = np.array([where[n] for n in info.column_names])
    order = np.concatenate([keep, own])
    reference = schur(full[np.ix_(order, order)], len(keep))
    cands = _chunks()[1]
    G = info.shared
    P = np.zeros(G)                   # the information before any nuisance is eliminated
    for c in cands:
        if c.kind == "static":
            D, prior = info.static_parts[c.key[:-1]]
            P += np.diag(D * c.dwell_s + prior)[:G]
        else:
            P += np.diag(info.rotation[c.key][1])[:G]
    p = np.sqrt(P)
    assert np.all(p > 0)
    error = np.max(np.abs(F - reference) / np.outer(p, p))
    assert error < TOL, error
    # the check can fail: the shared block of the full matrix (the groups' own columns dropped,
    # not eliminated) is far from it
    dropped = full[np.ix_(keep, keep)]
    assert np.max(np.abs(dropped - reference) / np.outer(p, p)) > 1e3 * TOL
    # and the search's 1σ of the reported parameters are the full matrix's, the covariance's ridge
    # (1e-10 of the unit diagonal) included as the search adds it (search.complement): to the
    # rounding of the eliminations above carried into the covariance (the positions' 1σ keep 1e-7 of
    # the information that entered: 1e-16 x 1e7 = 1e-9; measured 4.9e-9; 4.2e-8 when the ridge was
    # left out of the eliminated columns, 3.7e-9 with no ridge at all), so 1e-7
    _, F = _information(monkeypatch, eliminate=True, ridge=True)
    names = info.parameters.names
    full_names = full_info.parameters.names
    s_new = np.sqrt(np.diag(Scorer(info, cands, Criterion("D"), np.arange(3)).covariance_of(F)))
    s_full = np.sqrt(np.diag(Scorer(full_info, cands, Criterion("D"), np.arange(3)).covariance_of(full)))
    at = {n: k for k, n in enumerate(full_names)}
    ratio = np.array([s_new[k] / s_full[at[n]] for k, n in enumerate(names)])
    assert np.max(np.abs(ratio - 1.0)) < 1e-7, ratio


def test_a_vertical_groups_complement_is_cleaned_of_rounding_only(monkeypatch):
    """One vertical turn alone: its own columns take nearly all it tells of the positions, so the
    plain complement there is rounding of either sign (an indefinite matrix: negative variances in
    a known-attitude design with few turns).  search.complement (information.group_schur) is
    positive semi-definite and differs from the plain complement by at most ROUNDING (1e-12) of the
    information that entered it (scaled to a unit diagonal before the elimination); a level group
    keeps the plain complement, bit for bit."""
    from station.design import search
    from station.design.information import ROUNDING, group_schur

    info, _ = _information(monkeypatch, eliminate=True)
    G = info.shared
    _, cands = _chunks()
    vertical = [c for c in cands if c.kind == "rotation" and c.axis[1] == 90.0]
    level = [c for c in cands if c.kind == "rotation" and c.axis[1] == 0.0]
    # (4 columns per rate: two rates)
    assert info.own_columns == {c.axis: 8 for c in vertical}
    for c in vertical:
        S = info.group_prior[c.axis] + info.rotation[c.key][1]
        d = np.sqrt(np.diag(S)[:G])
        d[d == 0] = 1.0
        plain = schur(S, G) / np.outer(d, d)
        clean = search.complement(info, c.axis, S, G) / np.outer(d, d)
        # (without the covariance's ridge on the group's own columns: the plain complement to rounding)
        exact = group_schur(S, G, info.own_columns[c.axis], 0.0) / np.outer(d, d)
        # (the eigenvalues of V w V^T as computed: rounding of G eps x the largest, 4 here: ~4e-14)
        assert np.min(np.linalg.eigvalsh(clean)) >= -1e-13
        # (G eigenvalues each moved by at most ROUNDING: an entry by at most G x ROUNDING)
        assert np.max(np.abs(exact - plain)) <= G * ROUNDING
        # the ridge (search.RIDGE, 1e-10 of the own columns' diagonal) moves it by ~1e-10 at most
        assert np.max(np.abs(clean - plain)) <= 10 * search.RIDGE
    for c in level:
        S = info.group_prior[c.axis] + info.rotation[c.key][1]
        assert np.array_equal(search.complement(info, c.axis, S, G), schur(S, G))

"""The safe path of a probe plan: moves between stand-offs that keep the ball clear
of the stock, the order of the points (nearest neighbour, then 2-opt) and the
predicted gauging time. See `_plan` for the rules."""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..geometry import CHORD_ERROR_MM, feature_polyline, path_distance, profile_kind

_SAFE = 3 * CHORD_ERROR_MM  # see _plan


def _profile_polyline(profile) -> np.ndarray:
    parts = [feature_polyline(f) for f in profile.features]
    return np.vstack([parts[0]] + [p[1:] for p in parts[1:]])


def retract_x(study, s) -> float:
    """The retract line's X (radius, mm): clear of the stock by the clearance, beyond
    the largest radius of a shaft or inside the smallest of a bore (`[profile] kind`)."""
    poly = _profile_polyline(study.profile)
    grow = s.stock + study.probe.ball_radius + s.clearance
    if profile_kind(study.profile) == "internal":  # the study's declared [profile] kind
        x = float(poly[:, 0].min()) - grow
        if x < 0.0:
            raise InputError(
                f"the bore (smallest radius {poly[:, 0].min():g} mm) is too small for the "
                f"ball with stock and clearance ({grow:g} mm): no retract line inside it",
                file=str(study.path),
                value=float(poly[:, 0].min()),
            )
        return x
    return float(poly[:, 0].max()) + grow


def _clear(a, b, poly, need) -> bool:
    return path_distance(a, b, poly) >= need - _SAFE


def _route(a, b, x_ret, poly, need):
    """The moves from stand-off `a` to `b`: straight when clear, else out to the
    retract line, along it and in; None when even that is not clear."""
    if _clear(a, b, poly, need):
        return [b]
    legs = [(x_ret, a[1]), (x_ret, b[1]), b]
    prev = a
    for p in legs:
        if p != prev and not _clear(prev, p, poly, need):
            return None
        prev = p
    return legs


def _length(a, moves) -> float:
    total, prev = 0.0, a
    for p in moves:
        total += float(np.hypot(p[0] - prev[0], p[1] - prev[1]))
        prev = p
    return total


def _two_opt(order, cost):
    """2-opt on an open tour starting at node 0 (home)."""
    order = list(order)
    improved = True
    while improved:
        improved = False
        for i in range(1, len(order) - 1):
            for j in range(i + 1, len(order)):
                a, b = order[i - 1], order[i]
                c = order[j]
                d = order[j + 1] if j + 1 < len(order) else None
                old = cost[a, b] + (cost[c, d] if d is not None else 0.0)
                new = cost[a, c] + (cost[b, d] if d is not None else 0.0)
                if new < old - 1e-9:
                    order[i : j + 1] = order[i : j + 1][::-1]
                    improved = True
    return order


def order_and_route(study, s, raw):
    """`(home, ordered raw points, path, travel mm, time s)` for the raw points
    `(feature, t, contact, centre, approach, start, target, inside)`."""
    poly = _profile_polyline(study.profile)
    r = study.probe.ball_radius
    need = r + s.stock + s.clearance
    x_ret = retract_x(study, s)
    z_front = float(poly[:, 1].max()) + need
    home = (x_ret, z_front)
    nodes = [home] + [p[5] for p in raw]
    n = len(nodes)
    routes: dict[tuple[int, int], list] = {}
    cost = np.full((n, n), np.inf)
    for i in range(n):
        for j in range(n):
            if i == j:
                continue
            if j < i and (j, i) in routes and routes[(j, i)] is not None:
                back = routes[(j, i)]
                rev = [*back[:-1][::-1], nodes[j]]
                routes[(i, j)] = rev
                cost[i, j] = cost[j, i]
                continue
            mv = _route(nodes[i], nodes[j], x_ret, poly, need)
            routes[(i, j)] = mv
            if mv is not None:
                cost[i, j] = _length(nodes[i], mv)
    for k in range(1, n):
        if not np.isfinite(cost[0, k]):
            fid, t = raw[k - 1][0], raw[k - 1][1]
            raise InputError(
                f"feature {fid!r} at t={t:.3f}: no move reaches the probe's stand-off "
                "keeping the clearance from the stock (an undercut)",
                file=str(study.path),
                feature=fid,
            )
    # nearest neighbour from home, then 2-opt
    order, left = [0], set(range(1, n))
    while left:
        last = order[-1]
        nxt = min(left, key=lambda k: (cost[last, k], k))
        order.append(nxt)
        left.remove(nxt)
    order = _two_opt(order, cost)
    path, travel, probe_len = [], 0.0, 0.0
    for a, b in zip(order[:-1], order[1:], strict=True):
        for p in routes[(a, b)]:
            path.append(("rapid", p))
        travel += cost[a, b]
        pt = raw[b - 1]
        path.append(("probe", pt[6]))
        path.append(("rapid", pt[5]))
        probe_len += float(np.hypot(pt[5][0] - pt[3][0], pt[5][1] - pt[3][1]))
    back = _route(nodes[order[-1]], home, x_ret, poly, need) or [home]
    for p in back:
        path.append(("rapid", p))
    travel += _length(nodes[order[-1]], back)
    rapid = travel + probe_len  # the retracts after each touch are rapid too
    feed = study.probe.feed
    time_s = 60.0 * (rapid / s.rapid_feed + probe_len / feed)
    ordered = [raw[k - 1] for k in order[1:]]
    return home, ordered, tuple(path), float(travel + 2 * probe_len), float(time_s)

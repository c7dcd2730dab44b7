"""The files of a simulated data set: a probe CSV as a machine writes it and a
study file for a profile (X written as diameters)."""

from __future__ import annotations

import numpy as np

from ..geometry import Arc, MachineTransform, Profile, drawn_limits


def probe_csv_text(
    sim: dict, *, part: str | None = None, x_mode: str = "diameter", header: str = ""
) -> str:
    """The probe CSV a machine would write for ``sim`` (X doubled in diameter mode)."""
    xs = 2.0 if x_mode == "diameter" else 1.0
    lines = [f"# {line}" for line in header.splitlines()]
    lines.append(
        ",".join((["part"] if part else []) + ["feature", "x", "z", "approach_x", "approach_z"])
    )
    lead = f"{part}," if part else ""
    cols = [
        np.asarray(sim[k], dtype=float)[:, j].tolist()
        for k in ("points", "approach")
        for j in (0, 1)
    ]
    lines += [
        f"{lead}{fid},{x * xs:.5f},{z:.5f},{ax:.6f},{az:.6f}"
        for fid, x, z, ax, az in zip(sim["feature"], *cols, strict=True)
    ]
    return "\n".join(lines) + "\n"


def _toml_point(p, xs):
    return f"[{p[0] * xs:.4f}, {p[1]:.4f}]"


def study_toml_text(
    profile: Profile,
    *,
    name: str,
    probe_files: list[str],
    program: str | None,
    ball_radius: float,
    ball_radius_u: float,
    repeatability: float,
    transform: MachineTransform,
    extra: str = "",
) -> str:
    """A study file for ``profile`` (X written as diameters)."""
    out = [
        "# piecs_bayes study file (see docs/formats.md). Lengths in mm.",
        "[study]",
        f'name = "{name}"',
        'units = "mm"',
        "probe_files = [" + ", ".join(f'"{p}"' for p in probe_files) + "]",
    ]
    if program:
        out.append(f'part_program = "{program}"')
    out += [
        "",
        "[profile]",
        'kind = "external"',
        'x_mode = "diameter"        # X of the points below are diameters',
        "tangent_tolerance_deg = 0.5",
    ]
    for f in profile.features:
        out += ["", "[[profile.feature]]", f'id = "{f.id}"', f'type = "{f.kind}"']
        out.append(f"start = {_toml_point(f.p0, 2)}")
        out.append(f"end = {_toml_point(f.p1, 2)}")
        if isinstance(f, Arc):
            out.append(f"center = {_toml_point(f.center, 2)}")
            out.append(f'direction = "{"ccw" if f.ccw else "cw"}"')
        lo, hi = drawn_limits(f)
        out += [f"tolerance = [{lo:.4f}, {hi:.4f}]", f'tolerance_on = "{f.tolerance_on}"']
    out += [
        "",
        "[probe]",
        f"ball_radius = {ball_radius}",
        f"ball_radius_u = {ball_radius_u}",
        f"repeatability = {repeatability}",
        'x_mode = "diameter"         # the probe files write X as diameters',
        "tool = 9                    # the probe is tool 9 (T0909 / T9 M6)",
        "feed = 200.0                # probing feed (mm/min): the calibration holds at this feed",
        "",
        "[machine]                    # machine -> part transform",
        f"x_centre = {transform.x_centre}",
        f"z_offset = {transform.z_offset}",
        f"scale_x = {transform.scale_x}",
        f"scale_z = {transform.scale_z}",
        f"rotation = {transform.rotation}",
    ]
    return "\n".join(out) + "\n" + extra

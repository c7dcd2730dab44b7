"""Report sections on what goes to the machine: the adjusted part program, the
error specification and the tool-offset update."""

from __future__ import annotations

import numpy as np

from .model import Para, Pre, Table, micro, num


def program_section(res) -> list:
    adj = res.program
    if adj is None:
        why = res.unavailable.get("program", "switched off")
        return [
            Para(
                f"No adjusted part program: {why}",
                "warn" if "program" in res.unavailable else "note",
            )
        ]
    study = res.study
    rows = [
        [
            str(c.line),
            c.feature or "(approach)",
            c.old.strip(),
            c.new.strip(),
            num(c.shift_mm, ".1f"),
        ]
        for c in adj.changes
    ]
    nose = (
        f"checked for gouges with a nose radius of {res.nose_radius:g} mm"
        if res.nose_radius is not None
        else "not checked with the nose radius (give one: [offsets] current_r or --nose-radius)"
    )
    return [
        Para(
            f"{study.program.name}: {len(adj.changes)} blocks rewritten, largest end-point move "
            f"{adj.max_shift_mm * 1e3:.1f} µm (limit {study.compensation.max_correction * 1e3:g} "
            f"µm); every other line is byte-identical; {nose}. Mapping of blocks to features: "
            + ", ".join(f"{k} {list(v)}" for k, v in adj.mapping.features.items())
            + "."
        ),
        Table(
            ["line", "feature", "original", "adjusted", "end moved (µm)"],
            rows,
            caption="Rewritten blocks.",
        ),
        Pre(
            adj.diff.splitlines(),
            caption="Unified diff against the original program",
            diff=True,
            pdf=False,
        ),
    ]


def errspec_section(res) -> list:
    blocks: list = []
    spec = res.errspec
    if spec is None:
        why = res.unavailable.get("errspec", "switched off")
        blocks.append(Para(f"No error specification: {why}", "warn"))
    else:
        rows = []
        for t in spec.tables:
            pos = np.asarray(t.position, dtype=float)
            corr = np.asarray(t.correction, dtype=float)
            u = np.asarray(t.u_correction, dtype=float)
            rows.append(
                [
                    t.name,
                    f"{t.axis.upper()} vs {t.position_axis.upper()}",
                    str(len(pos)),
                    f"{pos.min():.3f} … {pos.max():.3f}",
                    num(float(np.max(np.abs(corr))), ".2f"),
                    num(float(np.max(u)), ".2f"),
                    "yes" if t.axis == t.position_axis else "no (depends on another axis)",
                ]
            )
        blocks += [
            Para(
                f"{spec.description}. Corrections are −gain × error along the corrected machine "
                "axis, machine positions, X as radius (native format: compensation.errspec.json "
                "and one CSV per table)."
            ),
            Table(
                [
                    "table",
                    "corrects",
                    "rows",
                    "positions (mm)",
                    "max |correction| (µm)",
                    "max u (µm)",
                    "LinuxCNC joint table",
                ],
                rows,
            ),
        ]
    upd = res.offsets
    if upd is None:
        blocks.append(Para("No tool-offset update.", "note"))
    else:
        rows = []
        for a in upd.axes:
            if a.error is None:
                rows.append([a.axis.upper(), "not measured", "–", "–", "–"])
                continue
            rows.append(
                [
                    a.axis.upper(),
                    f"{num(a.error)} ± {num(a.u_error, '.2f')}",
                    f"{num(a.correction)} ± {num(a.u_correction, '.2f')}",
                    a.status,
                    a.reason,
                ]
            )
        state = "BLOCKED" if upd.blocked else ("update" if upd.any_update else "no change")
        blocks += [
            Para(
                f"Tool-offset (wear) update for tool {upd.tool}: {state}; X as {upd.x_mode} (µm)."
            ),
            Table(["axis", "error ± u (µm)", "correction ± u (µm)", "status", "why"], rows),
        ]
        notes = [micro(n) for n in (*upd.reasons, *res.offset_notes)]
        if notes:
            blocks.append(Pre([f"- {n}" for n in notes], caption="Notes"))
    return blocks

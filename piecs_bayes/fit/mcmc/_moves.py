r"""One vocabulary of ensemble moves for every sampler the package offers.

A move set is named once here (`MOVES`) and means the same mixture in
[`sample_posterior`][piecs_bayes.fit.sample_posterior] (emcee itself) and in
[`sample_posteriors`][piecs_bayes.fit.sample_posteriors] (the lockstep ensembles):
`"stretch"` (Goodman & Weare, $a = 2$, emcee's `StretchMove`) or `"de"` (80 %
differential evolution, emcee's `DEMove` with $\gamma_0 = 2.38/\sqrt{2d}$, and 20 %
stretch), drawn per ensemble and step. [`check_moves`][] validates a name,
[`emcee_moves`][] gives emcee's move list. emcee's snooker move is never offered (emcee
3.1.6's is biased); [`snooker_move_is_sound`][] checks the installed emcee numerically.

The moves and the snooker bug: docs/models/sampling.md, "Moves".
"""

from __future__ import annotations

import math

import numpy as np

from ...errors import InputError

#: the names a user may pass as ``moves`` (``None`` means ``"stretch"``)
MOVES = ("stretch", "de")
#: share of differential-evolution steps in ``"de"`` (the rest are stretch steps)
DE_FRACTION = 0.8
#: the stretch move's scale parameter ``a`` (emcee's default)
STRETCH_A = 2.0
#: the DE move's relative jitter of gamma (emcee's default ``sigma``)
DE_SIGMA = 1e-5


def de_gamma0(ndim: int) -> float:
    """The DE move's mean step scale, $2.38/\\sqrt{2d}$ (ter Braak 2006, emcee's default)."""
    return 2.38 / math.sqrt(2.0 * ndim)


def check_moves(moves: str | None) -> str:
    """The canonical name of a move set; ``None`` is ``"stretch"``. Anything else
    (``"de_snooker"`` included, see the module doc) is an `InputError`."""
    name = "stretch" if moves is None else moves
    if name not in MOVES:
        hint = (
            "; the DE snooker move is not offered: emcee 3.1.6's DESnookerMove is biased"
            if isinstance(name, str) and "snooker" in name.lower()
            else ""
        )
        raise InputError(
            f"moves: got {moves!r}, expected None, {', '.join(map(repr, MOVES))}{hint}",
            value=moves,
        )
    return name


def emcee_moves(moves: str | None):
    """The emcee ``moves`` argument for a move set name: a list of ``(move, weight)``."""
    import emcee

    name = check_moves(moves)
    stretch = emcee.moves.StretchMove(a=STRETCH_A)
    if name == "stretch":
        return [(stretch, 1.0)]
    de = emcee.moves.DEMove(sigma=DE_SIGMA)  # gamma0 default: 2.38 / sqrt(2 d)
    return [(de, DE_FRACTION), (stretch, round(1.0 - DE_FRACTION, 12))]


class _FixedRandom:
    """A stand-in random state: picks the first walker of each set, never shuffles."""

    @staticmethod
    def randint(n):
        return 0

    @staticmethod
    def shuffle(x):
        return None


def snooker_move_is_sound() -> bool:
    """Whether the installed emcee's `DESnookerMove` projects on a unit vector.

    One proposal with every random choice fixed: the walker at $(4, 0)$, the
    snooker centre $z$ at the origin, $z_1 = (1, 0)$, $z_2 = 0$. The correct move
    is $q = s + \\gamma\\,u\\,(u\\cdot z_1 - u\\cdot z_2)$ with $u = (1, 0)$,
    i.e. a step of $\\gamma$; emcee 3.1.6 steps $4\\gamma$.
    """
    import emcee

    move = emcee.moves.DESnookerMove(gammas=1.0)
    s = np.array([[4.0, 0.0]])
    c = [np.array([[0.0, 0.0]]), np.array([[1.0, 0.0]]), np.array([[0.0, 0.0]])]
    try:
        q, _ = move.get_proposal(s, c, _FixedRandom())
    except Exception:  # noqa: BLE001 - another emcee API: treat as unknown, unsound
        return False
    return bool(np.allclose(q[0] - s[0], [1.0, 0.0]))

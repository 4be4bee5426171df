"""Fold location (Illinois regula falsi on the tangent's ``p``-component) and the
:class:`IllinoisBracket` it uses (also the period-doubling search's,
:func:`hbgear.engine.bifurcation.locate_period_doublings`)."""

from __future__ import annotations

from typing import NamedTuple

from .corrector import _Point

__all__ = ["IllinoisBracket"]


class IllinoisBracket(NamedTuple):
    """A sign-changing bracket ``f(a) f(b) <= 0`` narrowed by Illinois regula falsi.

    :meth:`point` is the next evaluation point; :meth:`narrowed` keeps the sub-bracket that
    still changes sign and halves the stale end's value when the same end is kept twice.
    """

    a: float
    fa: float
    b: float
    fb: float
    side: int = 0

    def point(self) -> float:
        return (self.a * self.fb - self.b * self.fa) / (self.fb - self.fa)

    def within(self, rel_tol: float) -> bool:
        """Whether the bracket is at most `rel_tol` wide, relative to ``max(|a|, |b|)``."""
        return abs(self.b - self.a) <= rel_tol * max(abs(self.a), abs(self.b))

    def narrowed(self, c: float, fc: float) -> IllinoisBracket:
        if fc * self.fa > 0:
            return IllinoisBracket(c, fc, self.b, self.fb * 0.5 if self.side == -1 else self.fb, -1)
        return IllinoisBracket(self.a, self.fa * 0.5 if self.side == 1 else self.fa, c, fc, 1)


#: The fold search stops when the unit tangent's p-component is below this (or the bracket is
#: ~1e-13 of the step): near a fold ``p(s) = p_f - c (s - s_f)^2`` and that component is
#: ``-2 c (s - s_f)``, so the fold's parameter is then off by ~``FOLD_TANGENT_TOL^2 / (4 c)``.
#: On the Duffing curve (H = 7) 1e-9 takes 2 and 4 corrector solves for its two folds where
#: 1e-12 took 4 and 5, the fold frequencies equal to all 16 digits (1e-6: 3.6e-12 off).
FOLD_TANGENT_TOL = 1e-9


def _locate_fold(correct, y0, t0, y1, g1, max_iter, max_steps=40):
    """The turning point between two converged points: zero of the tangent's p-component along
    the arc, parametrised by ``s = t0 . (y - y0)``, by Illinois regula falsi."""
    h = float(t0 @ (y1 - y0))

    def at(s):
        point = correct(y0 + s * t0, t0, float(t0 @ y0) + s, max_iter, t0)
        if not isinstance(point, _Point):
            return None, None
        return point, point.tangent[-1]

    bracket = IllinoisBracket(0.0, float(t0[-1]), h, g1)
    best = None
    for _ in range(max_steps):
        s = bracket.point()
        point, g = at(s)
        if point is None:
            return best
        best = point
        if abs(g) < FOLD_TANGENT_TOL or abs(bracket.b - bracket.a) < 1e-13 * max(abs(h), 1e-300):
            return point
        bracket = bracket.narrowed(s, g)
    return best


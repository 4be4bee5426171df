r"""Friction-coefficient laws at the tooth contact (MODEL.md section 3).

Each law is a small frozen dataclass, registered as a JAX pytree so that its parameters can
be traced (continuation in ``mu0``, vmap over a batch of laws), with one method

    mu(vs, vr, load_per_width, xp) -> signed friction coefficient,

where ``vs`` is the sliding velocity ``V_s`` [m/s] (its sign carries the direction), ``vr`` the
rolling (sum) velocity ``V_r`` [m/s] and ``load_per_width`` the normal load per unit face width
[N/m]. ``xp`` is the array module (``numpy`` for time integration, ``jax.numpy`` for harmonic
balance): the laws use only arithmetic and ``xp`` functions, so one definition serves both.

Adding a law means adding a class here and an entry in :data:`LAWS`; nothing else changes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from jax.tree_util import register_dataclass

from .kelley_lemanski import kelley_lemanski_magnitude

__all__ = ["FrictionLaw", "NoFriction", "Coulomb", "Arctan", "KelleyLemanski", "LAWS"]


class FrictionLaw:
    """Abstract friction law: ``mu(vs, vr, load_per_width, xp)``, signed like ``vs``."""

    name: ClassVar[str]
    #: True when mu jumps at vs = 0 (needs a regularisation when vs depends on the state).
    discontinuous: ClassVar[bool] = False

    def mu(self, vs, vr, load_per_width, xp=np):  # pragma: no cover - abstract
        raise NotImplementedError

    def regularized(self, v_reg_m_per_s: float) -> FrictionLaw:
        """The law with ``sgn(vs)`` replaced by ``(2/pi) atan(vs / v_reg)`` (itself if smooth)."""
        return self


@register_dataclass
@dataclass(frozen=True)
class NoFriction(FrictionLaw):
    r"""No friction, $\mu = 0$."""

    name: ClassVar[str] = "none"

    def mu(self, vs, vr, load_per_width, xp=np):
        return 0.0 * vs


@register_dataclass
@dataclass(frozen=True)
class Coulomb(FrictionLaw):
    r"""Coulomb law, $\mu = \mu_0 \,\mathrm{sgn}(V_s)$.

    **Arguments:** `mu0`: friction coefficient [-].
    """

    mu0: float = 0.1
    name: ClassVar[str] = "coulomb"
    discontinuous: ClassVar[bool] = True

    def mu(self, vs, vr, load_per_width, xp=np):
        return self.mu0 * xp.sign(vs)

    def regularized(self, v_reg_m_per_s: float) -> FrictionLaw:
        return Arctan(self.mu0, v_reg_m_per_s)


@register_dataclass
@dataclass(frozen=True)
class Arctan(FrictionLaw):
    r"""Smoothed Coulomb law (paper Eq. 3), $\mu = (2\mu_0/\pi)\arctan(V_s/V_0)$.

    **Arguments:** `mu0`: friction coefficient reached at large sliding speed [-];
    `v0`: reference sliding speed setting the slope at the pitch point [m/s].
    """

    mu0: float = 0.1
    v0: float = 0.01
    name: ClassVar[str] = "arctan"

    def mu(self, vs, vr, load_per_width, xp=np):
        return (2.0 * self.mu0 / np.pi) * xp.arctan(vs / self.v0)


@register_dataclass
@dataclass(frozen=True)
class KelleyLemanski(FrictionLaw):
    r"""Kelley--Lemanski / Benedict--Kelley empirical law for mixed lubrication.

    $\mu = \mathrm{sgn}(V_s)\,\min(\mu_\mathrm{KL}(|V_s|, V_r, w, \eta_0, R_q), \mu_\mathrm{cap})$ with
    $\mu_\mathrm{KL} = 0.0127\, C_R \log_{10}(C_3 w/(\eta_0 V_s V_r^2))$: the form of the paper's Eq. 2
    without its curvature factor $(\rho_p+\rho_g)^2$, with Benedict & Kelley's (1961) constants (the
    paper gives none); constants, units and sources in ``docs/kelley_lemanski.md``.

    **Arguments:** `viscosity_Pa_s`: lubricant dynamic viscosity $\eta_0$ [Pa s];
    `roughness_um`: composite RMS surface roughness [um]; `v_reg`: when > 0, ``sgn`` is
    replaced by ``(2/pi) atan(vs/v_reg)`` [m/s].
    """

    viscosity_Pa_s: float = 0.01
    roughness_um: float = 0.5
    v_reg: float = 0.0
    name: ClassVar[str] = "kelley-lemanski"
    discontinuous: ClassVar[bool] = True

    def mu(self, vs, vr, load_per_width, xp=np):
        magnitude = kelley_lemanski_magnitude(
            xp.abs(vs), xp.abs(vr), load_per_width, self.viscosity_Pa_s, self.roughness_um, xp=xp
        )
        if isinstance(self.v_reg, (int, float)) and self.v_reg == 0.0:
            sign = xp.sign(vs)
        else:  # v_reg may be traced: sgn where it is 0 (no 0/0, no infinite derivative)
            smooth = self.v_reg > 0.0
            regularized = (2.0 / np.pi) * xp.arctan(vs / xp.where(smooth, self.v_reg, 1.0))
            sign = xp.where(smooth, regularized, xp.sign(vs))
        return magnitude * sign

    def regularized(self, v_reg_m_per_s: float) -> FrictionLaw:
        return KelleyLemanski(self.viscosity_Pa_s, self.roughness_um, v_reg_m_per_s)


#: Config name -> law class.
LAWS: dict[str, type[FrictionLaw]] = {
    law.name: law for law in (NoFriction, Coulomb, Arctan, KelleyLemanski)
}


"""A stiffness and damping that move with the response's recent amplitude."""

from __future__ import annotations

from pidyn.params import ParamSpec
from pidyn.systems.terms.base import Array, ForceTerm, _clamp_min, _relu

#: how the stiffness and damping factors follow the envelope e
LAWS = ("linear", "bounded", "curved")
#: the curved law's exponent: 1 is the bounded law; above, the structure holds its small-amplitude
#: stiffness longer and softens faster in strong shaking
SHAPE_RANGE = (0.5, 4.0)


def _inside(value: float, lo: float, hi: float) -> float:
    """``value`` moved just inside (lo, hi): a box parameter's start must lie strictly within."""
    margin = 1e-6 * (hi - lo)
    return float(min(max(float(value), lo + margin), hi - margin))


class AmplitudeSoftening(ForceTerm):
    """- soft k e x + gain c e x': a stiffness that falls and a damping that rises with the
    response's recent amplitude e, and recover as it decays (soil at a bridge's abutments that
    softens in strong shaking and stiffens again in the coda; an equivalent-linear structure
    whose amplitude is a state, not a choice made per record).

    e' = (A / a_ref - e) / tau, with A = sqrt(x^2 + (x' / w0)^2) the oscillation's amplitude at
    the nominal circular frequency w0 (smooth; |x| ripples at twice the frequency) and ``a_ref``
    a typical amplitude of the record, so that e is about 1 in the strongest shaking and ``soft``
    and ``gain`` are the shares by which k and c have changed there.

    ``law="linear"``: k (1 - soft e) and c (1 + gain e), linear in soft and gain (what a regression
    screens). ``law="bounded"``: the same slopes at small e, but never a negative stiffness or
    damping, however far an earthquake drives e beyond the records the law was fitted on: a
    softening k / (1 + soft e) (the hyperbolic law of soil's modulus reduction, Hardin and
    Drnevich 1972), a stiffening k (1 + |soft| e); a damping c (1 + gain e) that rises, c / (1 +
    |gain| e) that falls. ``law="curved"``: the bounded law in e ** shape, the exponent identified
    (the modified hyperbolic law, Darendeli 2001): one law can then hold a structure stiff through
    moderate shaking and still soften it in the strongest, which the bounded law's fixed slope at
    small e cannot."""

    name = "amplitude_softening"
    n_latent = 1

    def __init__(
        self,
        soft: float = 0.1,
        gain: float = 0.1,
        tau: float = 2.0,
        a_ref: float = 1.0,
        w0: float = 1.0,
        stiffness: str = "k",
        damping: str = "c",
        tau_range: tuple[float, float] = (0.05, 60.0),
        law: str = "linear",
        shape: float = 1.0,
    ) -> None:
        if a_ref is None or w0 is None:  # a config's null: the run reads them from its records
            raise ValueError(
                f"{self.name}: a_ref and w0 are null; a run reads them from its records "
                "(system.a_ref=null system.w0=null), a system built directly needs numbers"
            )
        if not (a_ref > 0 and w0 > 0):
            raise ValueError(f"{self.name}: a_ref and w0 must be > 0, got {a_ref}, {w0}")
        if law not in LAWS:
            raise ValueError(f"{self.name}: law must be one of {LAWS}, got {law!r}")
        self.law = law
        # linear in soft and gain (regression columns) only under the linear law
        self.linear = ("soft", "gain") if law == "linear" else ()
        # the linear law's stiffness turns negative at soft e = 1; the bounded one never does; the
        # curved one, at e ** shape < e below e = 1, needs a larger share for the same softening there
        self.soft_range = (-0.5, 0.95) if law == "linear" else (-0.5, 20.0 if law == "bounded" else 50.0)
        self.tau_range = (float(tau_range[0]), float(tau_range[1]))
        # a fit that ended on a bound starts the next one just inside it (a box needs init inside)
        self.soft = _inside(soft, *self.soft_range)
        self.gain = _inside(gain, -0.9, 10.0)
        self.tau = _inside(tau, *self.tau_range)
        self.shape = _inside(shape, *SHAPE_RANGE)
        self.a_ref, self.w0 = float(a_ref), float(w0)
        self.stiffness, self.damping = stiffness, damping

    def specs(self):
        lo, hi = self.tau_range
        s_lo, s_hi = self.soft_range
        specs = [  # the bounds here are _inside's in __init__
            ParamSpec("soft", init=self.soft, true=self.soft, transform="box", lower=s_lo, upper=s_hi),
            ParamSpec("gain", init=self.gain, true=self.gain, transform="box", lower=-0.9, upper=10.0),
            ParamSpec("tau", init=self.tau, true=self.tau, transform="box", lower=lo, upper=hi, unit="s"),
        ]
        if self.law == "curved":
            a_lo, a_hi = SHAPE_RANGE
            specs.append(
                ParamSpec("shape", init=self.shape, true=self.shape, transform="box", lower=a_lo, upper=a_hi)
            )
        return specs

    def _measure(self, p: dict, e: Array) -> Array:
        """What the law reads of the envelope: e, or e ** shape under the curved law (e never
        below 0 from rest; the floor keeps the power's gradient finite there)."""
        if self.law != "curved":
            return e
        return _clamp_min(e, 1e-12) ** p["shape"]

    def factors(self, p: dict, e: Array) -> tuple[Array, Array]:
        """The factors on k and on c where the envelope is ``e``, by the term's law."""
        if self.law == "linear":
            return 1 - p["soft"] * e, 1 + p["gain"] * e
        soft, gain = p["soft"], p["gain"]
        e = self._measure(p, e)
        stiff = (1 + _relu(-soft) * e) / (1 + _relu(soft) * e)
        damp = (1 + _relu(gain) * e) / (1 + _relu(-gain) * e)
        return stiff, damp

    def force(self, t, x, v, z, p):
        e = z[..., 0]
        if self.law == "linear":
            return -p["soft"] * p[self.stiffness] * e * x + p["gain"] * p[self.damping] * e * v
        stiff, damp = self.factors(p, e)
        return (stiff - 1) * p[self.stiffness] * x + (damp - 1) * p[self.damping] * v

    def at_envelope(self, p: dict, e: Array) -> tuple[Array, Array]:
        """The structure's stiffness and damping where the envelope is ``e`` (by default k (1 -
        soft e) and c (1 + gain e)): what an equivalent-linear model at that amplitude would have."""
        stiff, damp = self.factors(p, e)
        return p[self.stiffness] * stiff, p[self.damping] * damp

    def latent_rate(self, t, x, v, z, p):
        amp = (x * x + (v / self.w0) ** 2 + (1e-9 * self.a_ref) ** 2) ** 0.5
        return ((amp / self.a_ref - z[..., 0]) / p["tau"])[..., None]

    def formula(self, p):
        if self.law in ("bounded", "curved"):  # the same force, written as what it adds to k x and c x'
            k, c, soft, gain = p[self.stiffness], p[self.damping], p["soft"], p["gain"]
            e = f"e^{p['shape']:.3g}" if self.law == "curved" else "e"
            sk = (
                f"- {soft:.4g} {k:.5g} {e}/(1 + {soft:.4g} {e}) x"
                if soft >= 0
                else f"+ {-soft:.4g} {k:.5g} {e} x"
            )
            sc = (
                f"+ {gain:.4g} {c:.5g} {e} x'"
                if gain >= 0
                else f"- {-gain:.4g} {c:.5g} {e}/(1 + {-gain:.4g} {e}) x'"
            )
            return f"{sk} {sc} (e' = (A/{self.a_ref:.3g} - e)/{p['tau']:.3g})"
        return (
            f"- {p['soft']:.4g} {p[self.stiffness]:.5g} e x + {p['gain']:.4g} {p[self.damping]:.5g} e x'"
            f" (e' = (A/{self.a_ref:.3g} - e)/{p['tau']:.3g})"
        )

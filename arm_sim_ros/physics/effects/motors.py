"""Geared motors: reflected rotor inertia, and optionally the windings.

Scene: `motors: {gear_ratio: [N1, N2], rotor_inertia: [J1, J2]}` adds Nᵢ²Jᵢ to Mᵢᵢ (the
diagonal "armature" model of MuJoCo and Drake; folded into the mass matrix's constants, so
it costs no code) and its kinetic energy counts in E through M.

With `resistance` R, `inductance` L and `torque_constant` k (all three or none) and an
optional `voltage_limit`, the winding currents i₁, i₂ join the state (initially 0): the
driver turns the requested joint torque τₐ into Vᵢ = clamp(Rᵢ τₐᵢ / (Nᵢ kᵢ), ±Vlimᵢ), the
winding obeys Lᵢ diᵢ/dt = Vᵢ − Rᵢ iᵢ − kᵢ Nᵢ q̇ᵢ and the joint receives Nᵢ kᵢ iᵢ. The stored
½ Lᵢ iᵢ² counts in E; `electrical_input` = ∫Σ Vᵢ iᵢ dt and `copper_loss` = ∫Σ Rᵢ iᵢ² dt.
When the request depends on the state the voltage clamp is switched like the effort clamp
(effort_limits.py): modes 0 (passes `va`) and ±1 (holds ±Vlimᵢ), located inside the step.
"""
from __future__ import annotations

from math import isfinite

from ..model import ParameterError
from ..stepping.stability import worst_stiffness
from .base import Channel, Effect, Parameter, clamp_guards, clamp_lines

ELECTRICAL = ("resistance", "inductance", "torque_constant")
VOLTAGE = 2                # where the voltage clamps' modes sit in the clamp modes


class Motors(Effect):
    name = "motors"
    drives = True
    parameters = (
        Parameter("gear_ratio", "pair", "1", "positive", description="joint turns N per motor turn"),
        Parameter("rotor_inertia", "pair", "kg m^2", "non-negative", default=(0.0, 0.0),
                  description="rotor inertia J on the motor side"),
        Parameter("resistance", "pair", "ohm", "positive", default=None,
                  description="winding resistance R"),
        Parameter("inductance", "pair", "H", "positive", default=None,
                  description="winding inductance L"),
        Parameter("torque_constant", "pair", "N m/A", "positive", default=None,
                  description="torque constant k = back-EMF constant in V s/rad"),
        Parameter("voltage_limit", "pair", "V", "positive", default=None,
                  description="driver voltage limit (none = unlimited)"),
    )

    def __init__(self, gear_ratio, rotor_inertia=(0.0, 0.0), resistance=None, inductance=None,
                 torque_constant=None, voltage_limit=None):
        self.gear_ratio, self.rotor_inertia = tuple(gear_ratio), tuple(rotor_inertia)
        given = [name for name, v in zip(ELECTRICAL, (resistance, inductance, torque_constant))
                 if v is not None]
        if given and len(given) != 3:
            raise ParameterError(f"motors: {', '.join(given)} given without "
                                 f"{', '.join(n for n in ELECTRICAL if n not in given)}; the "
                                 "windings need resistance, inductance and torque_constant")
        if voltage_limit is not None and not given:
            raise ParameterError("motors.voltage_limit needs the windings (resistance, "
                                 "inductance, torque_constant)")
        self.windings = bool(given)
        self.drives = self.windings      # only the windings stand between policy and joint
        self.resistance, self.inductance = resistance, inductance
        self.torque_constant, self.voltage_limit = torque_constant, voltage_limit
        self.state = ("i1", "i2") if self.windings else ()
        self.switching = False       # set by scene_effects: a clamp located as an event
        self._check_derived()

    def _check_derived(self) -> None:
        """The quantities the dynamics and the step plan derive must be doubles too: a
        torque_constant of 1e200 makes an electrical braking (k N)^2 / R beyond them."""
        for i, (n, j) in enumerate(zip(self.gear_ratio, self.rotor_inertia)):
            derived = [("reflected rotor inertia N^2 J", "kg m^2", lambda: n * n * j or 1.0)]
            if self.windings:
                k, r, l = self.torque_constant[i], self.resistance[i], self.inductance[i]
                derived += [("motor constant k N", "N m/A", lambda: k * n),
                            ("electrical braking (k N)^2 / R", "N m s/rad", lambda: (k * n) ** 2 / r),
                            ("winding pole R / L", "1/s", lambda: r / l),
                            ("drive gain R / (N k)", "V/(N m)", lambda: r / (n * k))]
            for what, unit, value in derived:
                try:
                    finite = isfinite(value()) and value() > 0
                except (OverflowError, ZeroDivisionError):
                    finite = False
                if not finite:
                    raise ParameterError(
                        f"motors: joint {i + 1}'s {what} ({unit}) is beyond double precision "
                        "with these values; give gear_ratio, rotor_inertia, resistance, "
                        "inductance and torque_constant at a motor's scale")

    @property
    def armature(self) -> tuple[float, float]:
        """Nᵢ² Jᵢ: the rotor inertia as the joint feels it."""
        return tuple(n * n * j for n, j in zip(self.gear_ratio, self.rotor_inertia))

    def constants(self, arm) -> dict:
        if not self.windings:
            return {}
        out = {}
        for i in (0, 1):
            n, r, l, k = (self.gear_ratio[i], self.resistance[i], self.inductance[i],
                          self.torque_constant[i])
            j = i + 1
            out |= {f"DRIVE{j}": r / (n * k), f"RES{j}": r, f"INV_IND{j}": 1.0 / l,
                    f"KN{j}": k * n}
            if self.voltage_limit is not None:
                out[f"VLIM{j}"] = self.voltage_limit[i]
        return out

    def terms(self) -> list[str]:
        return self.winding_terms(None)

    def mode_terms(self, mode) -> list[str]:
        return self.winding_terms(mode if self.switching else None)

    def winding_terms(self, mode) -> list[str]:
        """The drivers' voltages v, the windings' di/dt and the joint torques t: the voltage
        clamp switched in `mode` (a switching clamp), else written out (None)."""
        if not self.windings:
            return []
        lines = []
        for i in (0, 1):
            j = i + 1
            if mode is not None:
                lines += [f"va{j} = DRIVE{j} * t{j}",
                          *clamp_lines(f"va{j}", f"v{j}", f"VLIM{j}", mode[4][VOLTAGE + i])]
            elif self.voltage_limit is not None:
                lines.append(f"v{j} = MIN(MAX(DRIVE{j} * t{j}, -VLIM{j}), VLIM{j})")
            else:
                lines.append(f"v{j} = DRIVE{j} * t{j}")
            lines += [f"di{j} = (v{j} - RES{j} * i{j} - KN{j} * u{j}) * INV_IND{j}",
                      f"t{j} = KN{j} * i{j}"]
        return lines

    def guards(self, mode) -> list[tuple[str, str, int]]:
        return [g for i in (0, 1) for g in
                clamp_guards(f"va{i + 1}", f"VLIM{i + 1}", mode[4][VOLTAGE + i], "voltage", i)]

    def rates(self) -> list[str]:
        return ["di1", "di2"] if self.windings else []

    def channels(self):
        if not self.windings:
            return ()
        return (Channel("electrical_input", "v1 * i1 + v2 * i2", "input"),
                Channel("copper_loss", "RES1 * i1 * i1 + RES2 * i2 * i2", "loss"))

    def stored_energy(self, arm, q, extra) -> float:
        if not self.windings:
            return 0.0
        return 0.5 * (self.inductance[0] * extra[0] * extra[0]
                      + self.inductance[1] * extra[1] * extra[1])

    def linear_decay(self) -> tuple:
        """R/L of each winding: the currents' linear decay, integrated exactly by the
        exponential RK4 (stepping/exponential.py) where the scene runs it."""
        return tuple(r / l for r, l in zip(self.resistance, self.inductance)) if self.windings else ()

    def state_torques(self) -> tuple:
        """The joints receive k N i: the exponential step couples them exactly."""
        return (("KN1", 0), ("KN2", 1)) if self.windings else ()

    def coupling(self, arm) -> tuple:
        """((R/L, (kN)² Λ / L) per winding): the pole and the squared frequency at which
        winding and inertia exchange energy, of the linear test problem the stability plan
        checks the exponential step on (stability.exact_substeps)."""
        lam = worst_stiffness(arm)
        return tuple((r / l, (k * n) ** 2 * lam / l) for r, l, k, n in
                     zip(self.resistance, self.inductance, self.torque_constant, self.gear_ratio))

    def stiffness(self, arm, exact=False) -> float:
        if not self.windings:
            return 0.0
        # The winding's own pole −R/L, plus the electrical braking (kN)²/R it puts on the
        # joint (what a slow winding becomes: a damper), both real and negative. `exact`:
        # the pole is integrated exactly, the rest is checked by exact_substeps.
        electrical = 0.0 if exact else max(r / l for r, l in zip(self.resistance, self.inductance))
        braking = max((k * n) ** 2 / r for k, n, r in
                      zip(self.torque_constant, self.gear_ratio, self.resistance))
        return electrical + braking * worst_stiffness(arm)

    def frequency(self, arm, exact=False) -> float:
        if not self.windings or exact:
            return 0.0
        # Winding and inertia exchange energy: an oscillation at most sqrt((kN)² Λ / L).
        return max(k * n * (worst_stiffness(arm) / l) ** 0.5 for k, n, l in
                   zip(self.torque_constant, self.gear_ratio, self.inductance))

    def saturation(self, torque) -> str:
        """'' while each driver can ask for the requested joint torque `torque` (τₐ) within
        its voltage limit, else which joint asks for how much beyond it."""
        over = []
        for j, (t, limit) in enumerate(zip(torque, self.voltage_limit or ())):
            volts = self.resistance[j] / (self.gear_ratio[j] * self.torque_constant[j]) * t
            if abs(volts) > limit:
                over.append(f"joint {j + 1} asks for {volts:.4g} V beyond its {limit:g} V limit")
        return "; ".join(over) + (" (its joint gets less torque than requested; saturated "
                                  "steps are counted)" if over else "")

    def joint_torque(self, extra) -> tuple[float, float]:
        """What the joints receive from the windings' currents."""
        return tuple(k * n * i for k, n, i in zip(self.torque_constant, self.gear_ratio, extra))

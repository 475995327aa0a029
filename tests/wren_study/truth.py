"""The truth of the hybrid sounding-rocket study: Wren-H's motor and flight, written apart from rocketid.

Written from physics and the vehicle's declaration (``tests/vehicles/wren.py``: its sizes, the launcher, the
drag curve's knots), not from rocketid's code. Two parts:

**The motor** (:class:`Motor`): a nitrous-oxide / paraffin hybrid. The oxidiser is self-pressurizing liquid
N2O in a 24 l tank at saturation (vapour pressure, liquid and vapour densities, heat capacity from the
ESDU 91022 correlations; latent heat by Watson's rule from the normal boiling point). While liquid is left,
the tank is an equilibrium mixture: the liquid leaving is replaced by vapour boiled off the liquid, whose
latent heat cools it, so the tank pressure blows down (50.6 bar at 20 C to 36 bar at 9.2 s). With the last
kilogram of liquid the injector draws vapour too (the level reaches the outlet), its share rising smoothly to
all vapour: the thrust's knee; the pool left keeps boiling and cooling while the tank empties through the
vapour tail-off (zero thrust at 15.5 s, the tank at 2 bar at 21.8 s). Injector: single-phase orifice,
``mdot_ox = CdA sqrt(2 rho (p_tank - p_c))``, its valve opening over 0.2 s. Fuel: a cylindrical paraffin
port, regression ``rdot = a G_ox^n`` (a = 1.3e-4, n = 0.5, SI), the burning surface fading over +-2 mm of
web where the grain burns through. Chamber pressure from the characteristic velocity,
``p_c = eta c*(O/F) (mdot_ox + mdot_f) / A_t``, solved with the injector's flow at every instant; thrust
from the ideal nozzle (gamma 1.22, area ratio 4.5) at sea-level ambient pressure: the static firing's
conditions (the study's convention, as Tern-2's: the flight's thrust is the static firing's at the same
tank state and grain; an altitude-dependent pressure thrust is not one of this study's cases). Thrust and
mass flow are both outputs of the motor's state; neither is a scaled copy of a table.

**The flight** (:class:`Flight`): Cartesian position and velocity in the plane of flight about the centre
of a spherical, non-rotating Earth (radius 6371 km, inverse-square gravity with 9.80665 m/s^2 at sea
level); the pad at 1200 m above sea level. On the launch rail (6.1 m, its elevation) the rocket moves
along the rail once the thrust exceeds the weight's component along it; from rail exit it flies free: the
thrust along the body, which a statically stable finned rocket keeps along the air-relative velocity
(zero attack angle to the air: in a wind the body turns into it at once), drag against the air-relative
velocity, ``CD(M)`` piecewise linear on the declared knots (the truth's values), no lift. The 1976
standard atmosphere from its own hydrostatic layers, optionally warmer by ``dT`` at every altitude.
``solve_ivp`` (DOP853, rtol 1e-12) restarted at every corner of the motor's history.

**The GPS** (:func:`measurements`): downrange (great-circle distance from the pad), altitude above sea
level and speed at 10 Hz from ``wren.T_GPS`` (the receiver re-acquires its fix after the launch's shock) to
``wren.TF`` (apogee: the drogue fires there); 2 % of the fixes lost (seeded); seeded Gaussian noise at
``wren.SIGMA`` (the vertical three times the horizontal error), rounded to the log's resolution; no sigma
on the channels (the diagnosis estimates them).
"""

from __future__ import annotations

import functools
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

_VEHICLES = Path(__file__).resolve().parent.parent / "vehicles"
if str(_VEHICLES) not in sys.path:
    sys.path.insert(0, str(_VEHICLES))

import wren as V  # noqa: E402  (sizes, launcher, the drag curve's knots and values, the GPS's sampling)

EARTH_RADIUS = 6_371_000.0
STD_GRAVITY = 9.80665
SEA_LEVEL_PRESSURE = 101_325.0

# ---------------------------------------------------------------------------------------------- nitrous oxide
N2O_TC, N2O_PC, N2O_RHOC = 309.57, 7.251e6, 452.0          # critical temperature K, pressure Pa, density kg/m^3
N2O_TB, N2O_HVAP_B = 184.67, 376.1e3                        # normal boiling point K, latent heat there J/kg


def n2o_vapour_pressure(T: float) -> float:
    """Saturation pressure (Pa) at ``T`` (K): ESDU 91022."""
    Tr = T / N2O_TC
    X = 1.0 - Tr
    return N2O_PC * math.exp((-6.71893 * X + 1.35966 * X ** 1.5 - 1.3779 * X ** 2.5 - 4.051 * X ** 5) / Tr)


def n2o_liquid_density(T: float) -> float:
    X = 1.0 - T / N2O_TC
    return N2O_RHOC * math.exp(1.72328 * X ** (1 / 3) - 0.83950 * X ** (2 / 3) + 0.51060 * X - 0.10412 * X ** (4 / 3))


def n2o_vapour_density(T: float) -> float:
    Y = N2O_TC / T - 1.0
    return N2O_RHOC * math.exp(-1.00900 * Y ** (1 / 3) - 6.28792 * Y ** (2 / 3) + 7.50332 * Y - 7.90463 * Y ** (4 / 3)
                               + 0.629427 * Y ** (5 / 3))


def n2o_latent_heat(T: float) -> float:
    """Watson's rule from the normal boiling point, J/kg."""
    return N2O_HVAP_B * ((1.0 - T / N2O_TC) / (1.0 - N2O_TB / N2O_TC)) ** 0.38


def n2o_liquid_heat_capacity(T: float) -> float:
    X = 1.0 - T / N2O_TC
    return 2499.73 * (1.0 + 0.023454 / X - 3.80136 * X + 13.0945 * X ** 2 - 14.518 * X ** 3)


# ---------------------------------------------------------------------------------------------------- nozzle
EXHAUST_GAMMA = 1.22
AREA_RATIO = 4.5


def _exit_pressure_ratio(eps: float = AREA_RATIO, g: float = EXHAUST_GAMMA) -> float:
    area = lambda M: (1 / M) * ((2 / (g + 1)) * (1 + (g - 1) / 2 * M * M)) ** ((g + 1) / (2 * (g - 1)))  # noqa: E731
    mach = brentq(lambda M: area(M) - eps, 1.0001, 10.0, xtol=1e-14)
    return (1 + (g - 1) / 2 * mach * mach) ** (-g / (g - 1))


EXIT_PRESSURE_RATIO = _exit_pressure_ratio()
_G = EXHAUST_GAMMA
CF_MOMENTUM = math.sqrt(_G) * (2 / (_G + 1)) ** ((_G + 1) / (2 * (_G - 1))) * \
    math.sqrt(2 * _G / (_G - 1) * (1 - EXIT_PRESSURE_RATIO ** ((_G - 1) / _G)))


@dataclass(frozen=True)
class MotorConfig:
    """A hybrid motor as loaded for one firing (defaults: the static firing the team's table comes from)."""

    tank_temperature: float = 293.15     # K, the N2O at saturation when the valve opens
    ox_load: float = 16.0                # kg of N2O in the tank
    tank_volume: float = 0.024           # m^3
    injector_cda: float = 2.6e-5         # m^2, discharge coefficient times area
    valve_opening: float = 0.2           # s, the run valve's opening time (smoothstep)
    throat_diameter: float = 0.034       # m
    grain_length: float = 0.45           # m
    port_radius: float = 0.024           # m, initial
    grain_radius: float = 0.060          # m, outer radius of the paraffin (the web ends there)
    web_spread: float = 0.002            # m, the burn-through spreads over +-this (the port is not uniform)
    liner_share: float = 0.1            # fuel flow from the ablating liner, as a share of the paraffin's
    regression_a: float = 1.3e-4         # rdot = a G^n, SI
    regression_n: float = 0.5
    fuel_density: float = 900.0          # kg/m^3, paraffin
    eta_cstar: float = 0.92
    eta_nozzle: float = 0.97
    ingestion_mass: float = 1.0          # kg of liquid left when vapour starts to be drawn into the injector
    end_pressure: float = 2.0e5          # Pa: the tank is taken as empty (flows stop) below this


class Motor:
    """One firing of the hybrid (module notes). ``run()`` integrates the tank and the grain; then ``thrust(t)``,
    ``mass_flow(t)``, ``consumed(t)`` (oxidiser plus fuel, kg) and ``chamber_pressure(t)`` at any time."""

    def __init__(self, config: MotorConfig = MotorConfig()):
        self.c = config
        self.throat_area = math.pi * config.throat_diameter ** 2 / 4
        self._run()

    # -- pieces
    def liquid_mass(self, m: float, T: float) -> float:
        rl, rg = n2o_liquid_density(T), n2o_vapour_density(T)
        return (self.c.tank_volume - m / rg) / (1 / rl - 1 / rg)

    @staticmethod
    def cstar(of: float) -> float:
        """Characteristic velocity (m/s) of N2O / paraffin: 1610 at O/F 7.5, falling to N2O's own
        decomposition (1000) far from it."""
        if of <= 0.0:
            return 1000.0
        u = of / 7.5
        return 1000.0 + 610.0 * (u * math.exp(1.0 - u)) ** 1.5

    def _valve(self, t: float) -> float:
        u = min(max(t / self.c.valve_opening, 0.0), 1.0)
        return u * u * (3.0 - 2.0 * u)

    def _burning(self, r: float) -> float:
        """The share of the port's surface still paraffin; where the web is gone the phenolic liner ablates,
        giving ``liner_share`` of the paraffin's fuel flow."""
        c = self.c
        paraffin = min(max((c.grain_radius + c.web_spread - r) / (2 * c.web_spread), 0.0), 1.0)
        return paraffin + (1.0 - paraffin) * c.liner_share

    def _fuel(self, mox: float, r: float) -> float:
        if mox <= 0.0:
            return 0.0
        c = self.c
        G = mox / (math.pi * r * r)
        rdot = c.regression_a * G ** c.regression_n
        return c.fuel_density * 2 * math.pi * r * c.grain_length * rdot * self._burning(r)

    def _chamber(self, t: float, p_tank: float, rho: float, r: float):
        """Oxidiser flow, fuel flow and chamber pressure that the injector and the nozzle agree on."""
        cda = self.c.injector_cda * self._valve(t)
        if cda <= 0.0 or p_tank <= SEA_LEVEL_PRESSURE or t < 0.0:
            return 0.0, 0.0, SEA_LEVEL_PRESSURE

        def pc_of(mox):
            mf = self._fuel(mox, r)
            of = mox / mf if mf > 0 else 1e9
            return max(self.c.eta_cstar * self.cstar(of) * (mox + mf) / self.throat_area, SEA_LEVEL_PRESSURE), mf

        hi = cda * math.sqrt(2 * rho * p_tank)
        mox = brentq(lambda q: q - cda * math.sqrt(2 * rho * max(p_tank - pc_of(q)[0], 0.0)), 0.0, hi,
                     xtol=1e-15, rtol=1e-14)
        pc, mf = pc_of(mox)
        return mox, mf, pc

    def _nozzle_thrust(self, pc: float) -> float:
        """Thrust at the static firing's (sea-level) ambient pressure; zero once the over-expanded nozzle
        gives no net thrust."""
        F = pc * self.throat_area * (self.c.eta_nozzle * CF_MOMENTUM
                                     + AREA_RATIO * (EXIT_PRESSURE_RATIO - SEA_LEVEL_PRESSURE / pc))
        return max(F, 0.0)

    # -- the two phases: liquid (m_ox, T, r, m_f) and vapour (m_ox, r, m_f)
    def _injector_inlet(self, m: float, T: float):
        """Tank pressure, density at the injector and the liquid's share of the outflow by mass: pure liquid
        until the last ``ingestion_mass`` kg of liquid, when vapour is drawn in with it (the level reaches
        the outlet and vortexes), its volume share rising smoothly to all vapour as the liquid runs out; the
        pool left keeps boiling, cooling, as the tank blows down."""
        ml = self.liquid_mass(m, T)
        rl, rg = n2o_liquid_density(T), n2o_vapour_density(T)
        u = min(max(ml / self.c.ingestion_mass, 0.0), 1.0)
        phi = u * u * (3.0 - 2.0 * u)                   # liquid volume fraction of the outflow
        rho_in = phi * rl + (1.0 - phi) * rg
        return n2o_vapour_pressure(T), rho_in, phi * rl / rho_in, ml

    def _rhs_liquid(self, t, y):
        m, T, r, _ = y
        p, rho_in, liquid_share, ml = self._injector_inlet(m, T)
        mox, mf, _ = self._chamber(t, p, rho_in, r)
        A = (self.liquid_mass(m + 1e-5, T) - self.liquid_mass(m - 1e-5, T)) / 2e-5
        B = (self.liquid_mass(m, T + 1e-4) - self.liquid_mass(m, T - 1e-4)) / 2e-4
        L = n2o_latent_heat(T)
        # the liquid boils to refill the volume the outflow leaves; its latent heat cools the liquid:
        # m_l c dT/dt = -L e, e = -(dm_l/dt) - (liquid out), dm_l/dt = -A mdot + B dT/dt
        dT = -L * (A * mox - liquid_share * mox) / (ml * n2o_liquid_heat_capacity(T) - L * B)
        G = mox / (math.pi * r * r)
        return [-mox, dT, self.c.regression_a * G ** self.c.regression_n * self._burning(r) if mox > 0 else 0.0, mf]

    def _run(self):
        c = self.c
        ml0 = self.liquid_mass(c.ox_load, c.tank_temperature)
        if not c.ingestion_mass < ml0 < c.ox_load:
            raise ValueError(f"tank state impossible: {ml0:.2f} kg liquid of {c.ox_load} kg")
        empty = lambda t, y: n2o_vapour_pressure(y[1]) - c.end_pressure  # noqa: E731
        empty.terminal, empty.direction = True, -1
        ingestion = lambda t, y: self.liquid_mass(y[0], y[1]) - c.ingestion_mass  # noqa: E731
        sol = solve_ivp(self._rhs_liquid, (0.0, 120.0), [c.ox_load, c.tank_temperature, c.port_radius, 0.0],
                        method="DOP853", rtol=1e-11, atol=1e-12, dense_output=True, events=(empty, ingestion),
                        max_step=0.05)
        if sol.status != 1:
            raise RuntimeError("the tank did not empty")
        self.t_empty = float(sol.t[-1])
        self.t_ingestion = float(sol.t_events[1][0])       # vapour starts to be drawn: the thrust's knee
        self._sol = sol
        self.final = tuple(float(v) for v in sol.y[:, -1])     # ox left, temperature, port radius, fuel burnt
        self.t_zero_thrust = self._find_zero_thrust()

    def _find_zero_thrust(self) -> float:
        t = np.linspace(self.t_ingestion, self.t_empty, 4001)
        F = np.array([self.thrust(float(u)) for u in t])
        k = np.flatnonzero(F <= 0.0)
        if k.size == 0:
            return self.t_empty
        a, b = t[max(k[0] - 1, 0)], t[k[0]]
        return brentq(self._signed_thrust, a, b, xtol=1e-12)

    # -- the history at any time
    def _state(self, t: float):
        """(p_tank, density at the injector, port radius) at t, or None before the valve opens and once the tank
        is empty."""
        if t <= 0.0 or t > self.t_empty:
            return None
        m, T, r, _ = self._sol.sol(t)
        p, rho_in, _, _ = self._injector_inlet(m, T)
        return p, rho_in, r

    def _signed_thrust(self, t: float) -> float:
        s = self._state(t)
        if s is None:
            return -1.0
        _, _, pc = self._chamber(t, s[0], s[1], s[2])
        return pc * self.throat_area * (self.c.eta_nozzle * CF_MOMENTUM
                                        + AREA_RATIO * (EXIT_PRESSURE_RATIO - SEA_LEVEL_PRESSURE / pc))

    @functools.lru_cache(maxsize=200_000)
    def flows(self, t: float):
        """(oxidiser flow, fuel flow, chamber pressure) at t."""
        s = self._state(t)
        if s is None:
            return 0.0, 0.0, SEA_LEVEL_PRESSURE
        return self._chamber(t, s[0], s[1], s[2])

    def thrust(self, t: float) -> float:
        return self._nozzle_thrust(self.flows(t)[2]) if 0.0 < t < self.t_empty else 0.0

    def mass_flow(self, t: float) -> float:
        mox, mf, _ = self.flows(t)
        return mox + mf

    def chamber_pressure(self, t: float) -> float:
        return self.flows(t)[2]

    def consumed(self, t: float) -> float:
        """Propellant gone from the vehicle by t (oxidiser out of the tank plus paraffin burnt), kg."""
        if t <= 0.0:
            return 0.0
        m, _, _, mf = self._sol.sol(min(t, self.t_empty))
        return float(self.c.ox_load - m + mf)

    def port_radius(self, t: float) -> float:
        return float(self._sol.sol(min(max(t, 0.0), self.t_empty))[2])

    def corners(self) -> list:
        """Times where the history has a kink (the flight's integration restarts there): the valve fully open,
        the thrust reaching zero, the tank empty, the burn-through's start and end."""
        out = {self.c.valve_opening, self.t_zero_thrust, self.t_empty}
        t = np.linspace(0.0, self.t_empty, 8001)
        r = self._sol.sol(t)[2]
        for edge in (self.c.grain_radius - self.c.web_spread, self.c.grain_radius + self.c.web_spread):
            for j in np.flatnonzero(np.diff(np.sign(r - edge))):
                out.add(float(brentq(lambda u: self._sol.sol(u)[2] - edge, t[j], t[j + 1], xtol=1e-13)))
        return sorted(out)


# ------------------------------------------------------------------------------------------------ atmosphere
GEOPOTENTIAL_RADIUS = 6_356_766.0
GAS_CONSTANT = 8.31432
MOLAR_MASS = 0.0289644
AIR_GAMMA = 1.4
#: 1976 standard layers: base geopotential altitude (m'), base temperature (K), lapse rate (K/m').
LAYERS = ((0.0, 288.15, -0.0065), (11_000.0, 216.65, 0.0), (20_000.0, 216.65, 0.001),
          (32_000.0, 228.65, 0.0028), (47_000.0, 270.65, 0.0), (51_000.0, 270.65, -0.0028),
          (71_000.0, 214.65, -0.002))


class Air:
    """The 1976 standard atmosphere with every temperature ``dT`` K higher, hydrostatic from the standard
    sea-level pressure, layer by layer in closed form."""

    def __init__(self, dT: float = 0.0):
        self.dT = dT
        self.k = STD_GRAVITY * MOLAR_MASS / GAS_CONSTANT
        bases = [SEA_LEVEL_PRESSURE]
        for (H0, T0, L), (H1, _, _) in zip(LAYERS[:-1], LAYERS[1:]):
            Tb = T0 + dT
            if L == 0.0:
                bases.append(bases[-1] * math.exp(-self.k * (H1 - H0) / Tb))
            else:
                bases.append(bases[-1] * ((Tb + L * (H1 - H0)) / Tb) ** (-self.k / L))
        self.bases = bases

    def at(self, z: float):
        """Temperature (K), pressure (Pa), density (kg/m^3), speed of sound (m/s) at geometric altitude z."""
        H = GEOPOTENTIAL_RADIUS * z / (GEOPOTENTIAL_RADIUS + z)
        j = 0
        while j + 1 < len(LAYERS) and H >= LAYERS[j + 1][0]:
            j += 1
        H0, T0, L = LAYERS[j]
        Tb = T0 + self.dT
        T = Tb + L * (H - H0)
        p = self.bases[j] * (math.exp(-self.k * (H - H0) / Tb) if L == 0.0 else (T / Tb) ** (-self.k / L))
        return T, p, p * MOLAR_MASS / (GAS_CONSTANT * T), math.sqrt(AIR_GAMMA * GAS_CONSTANT * T / MOLAR_MASS)


# ---------------------------------------------------------------------------------------------------- wind
def wind_speed(h: float, wind) -> float:
    """Horizontal wind (m/s, + downrange) at altitude h above sea level: ``(w10, core)`` is a surface wind
    ``w10`` at 10 m above the pad growing as ``(z / 10 m)^(1/7)`` to 1 km above it, then linearly to a jet
    core ``core`` at 9 km, falling off above it as a Gaussian of 3 km."""
    if not wind:
        return 0.0
    w10, core = wind
    z = h - V.PAD_ALTITUDE
    if z <= 0.0:
        return 0.0
    if z <= 1_000.0:
        return w10 * (z / 10.0) ** (1.0 / 7.0)
    w1 = w10 * 100.0 ** (1.0 / 7.0)
    top = JET_CORE - V.PAD_ALTITUDE
    if z <= top:
        return w1 + (core - w1) * (z - 1_000.0) / (top - 1_000.0)
    return core * math.exp(-0.5 * ((z - top) / 3_000.0) ** 2)


JET_CORE = 9_000.0


def base_drag_increment(mach: float) -> float:
    """A blunt base's power-off drag on the body's cross-section: the base pressure coefficient of a 6 inch
    boat-tail-less body (0.10 subsonic, peaking at 0.18 just past Mach 1)."""
    return 0.10 + 0.08 * math.exp(-0.5 * ((mach - 1.05) / 0.3) ** 2)


# ----------------------------------------------------------------------------------------------- the flight
@dataclass(frozen=True)
class Hidden:
    """The hidden effects (defaults: the flight as declared)."""

    tank_temperature: float = 293.15   # K, the N2O when the valve opens (the static firing's: 20 C)
    vented: float = 0.0                 # kg of N2O vented on the pad after the fill (the declared mass has it)
    grain_radius: float = 0.060         # m, the paraffin's outer radius (the web's end)
    web_spread: float = 0.002           # m, the burn-through's spread
    wind: tuple | None = None           # (at 10 m above the pad, at the 9 km jet core), m/s, + downrange
    elevation_deg: float | None = None  # the launch rail's true elevation (declared: wren.ELEVATION_DEG)
    dT: float = 0.0                     # air warmer than the 1976 standard at every altitude, K
    dm_payload: float = 0.0             # kg on board beyond the declared launch mass
    base_drag: bool = False             # power-off base drag once the jet stops filling the base
    bias_h: float = 0.0                 # GPS altitude bias, m
    tau: float = 0.0                    # GPS time tags late by tau, s (the receiver's solution latency)

    def motor_config(self) -> MotorConfig:
        return MotorConfig(tank_temperature=self.tank_temperature, ox_load=V.OX_LOAD - self.vented,
                           grain_radius=self.grain_radius, web_spread=self.web_spread)


@functools.lru_cache(maxsize=32)
def motor_of(config: MotorConfig) -> Motor:
    return Motor(config)


class Flight:
    """One flight with its hidden effects (module notes)."""

    def __init__(self, hidden: Hidden):
        self.hidden = hidden
        self.motor = motor_of(hidden.motor_config())
        self.air = Air(hidden.dT)
        self.mu = STD_GRAVITY * EARTH_RADIUS ** 2
        self.m_launch = V.M_LAUNCH + hidden.dm_payload - hidden.vented
        elevation = V.ELEVATION_DEG if hidden.elevation_deg is None else hidden.elevation_deg
        self.rail = np.array([math.cos(math.radians(elevation)), math.sin(math.radians(elevation))])
        self.pad = np.array([0.0, EARTH_RADIUS + V.PAD_ALTITUDE])

    #: The jet fills the base fully above 4 bar of chamber pressure, not at all below 2 bar (linear between).
    JET_FULL, JET_NONE = 4.0e5, 2.0e5

    def jet(self, t: float) -> float:
        """How much of the base the jet fills (1 while the motor burns, 0 once it has stopped)."""
        pc = self.motor.chamber_pressure(t)
        return min(max((pc - self.JET_NONE) / (self.JET_FULL - self.JET_NONE), 0.0), 1.0)

    def corners(self) -> list:
        """The motor's corners, and where the base-drag fade starts and ends."""
        out = list(self.motor.corners())
        if self.hidden.base_drag:
            m = self.motor
            for level in (self.JET_FULL, self.JET_NONE):
                out.append(brentq(lambda u: m.chamber_pressure(u) - level, m.t_ingestion, m.t_empty - 1e-9, xtol=1e-12))
        return sorted(out)

    def mass(self, t: float) -> float:
        return self.m_launch - self.motor.consumed(t)

    def forces(self, t: float, r: np.ndarray, u: np.ndarray):
        """Thrust direction (unit), thrust, aerodynamic force and gravity acceleration at a position and
        velocity (Cartesian, the Earth's centre at the origin)."""
        rn = math.hypot(*r)
        up = r / rn
        east = np.array([up[1], -up[0]])                 # downrange, in the plane
        h = rn - EARTH_RADIUS
        _, _, rho, a = self.air.at(h)
        air_u = u - wind_speed(h, self.hidden.wind) * east
        speed = float(math.hypot(*air_u))
        along = air_u / speed if speed > 1e-9 else up
        mach = speed / a
        cd = float(np.interp(mach, V.CD_KNOTS, V.CD_TRUTH))
        if self.hidden.base_drag:
            cd += base_drag_increment(mach) * (1.0 - self.jet(t))
        drag = -0.5 * rho * speed * speed * V.S_REF * cd * along
        return along, self.motor.thrust(t), drag, -self.mu / rn ** 2 * up

    def rhs_free(self, t, y):
        r, u = y[:2], y[2:]
        body, F, drag, g = self.forces(t, r, u)
        acc = (F * body + drag) / self.mass(t) + g
        return [u[0], u[1], acc[0], acc[1]]

    def rhs_rail(self, t, y):
        """Along the rail (s, ds/dt): thrust along it, drag and weight projected on it; held until the thrust
        exceeds the weight's component."""
        s, w = y
        r = self.pad + s * self.rail
        u = w * self.rail
        _, F, drag, g = self.forces(t, r, u)
        acc = (F * self.rail + drag) / self.mass(t) + g
        a_along = float(acc @ self.rail)
        if s <= 0.0 and w <= 0.0 and a_along <= 0.0:
            return [0.0, 0.0]
        return [w, a_along]

    @functools.cached_property
    def rail_exit(self):
        """(time, Cartesian state) when the rocket leaves the rail."""
        corners = [c for c in self.corners() if c < 5.0] + [5.0]
        y = np.array([0.0, 0.0])
        a = 0.0
        out = lambda t, y: y[0] - V.RAIL_LENGTH  # noqa: E731
        out.terminal, out.direction = True, 1
        for b in corners:
            sol = solve_ivp(self.rhs_rail, (a, b), y, method="DOP853", rtol=1e-12, atol=1e-12, events=out)
            if sol.status == 1:
                t = float(sol.t_events[0][0])
                s, w = sol.y_events[0][0]
                return t, np.concatenate([self.pad + s * self.rail, w * self.rail])
            y, a = sol.y[:, -1], b
        raise RuntimeError("the rocket did not leave the rail")

    def states(self, times):
        """The Cartesian state (X, Y, U, W) at ``times`` (sorted, after rail exit)."""
        times = np.asarray(times, float)
        t0, y = self.rail_exit
        if times.min() < t0:
            raise ValueError(f"asked for the flight at {times.min()} s, before rail exit at {t0:.4f} s")
        end = float(times.max())
        corners = [c for c in self.corners() if t0 < c < end] + [end]
        out = np.full((times.size, 4), np.nan)
        a = t0
        for b in corners:
            sol = solve_ivp(self.rhs_free, (a, b), y, method="DOP853", rtol=1e-12, atol=1e-9, dense_output=True)
            if not sol.success:
                raise RuntimeError(sol.message)
            sel = (times >= a) & (times <= b)
            if sel.any():
                out[sel] = sol.sol(times[sel]).T
            y, a = sol.y[:, -1], b
        return out


def outputs_of(states) -> dict:
    """Downrange (great-circle distance from the pad, on the sea-level sphere), altitude above sea level and
    speed of Cartesian states."""
    X, Y, U, W = states.T
    return {"x": EARTH_RADIUS * np.arctan2(X, Y), "h": np.hypot(X, Y) - EARTH_RADIUS, "v": np.hypot(U, W)}


def exact_outputs(hidden: Hidden, times) -> dict:
    """The GPS's exact readings (its hidden errors included, no noise) at the tags ``times``."""
    tags = np.asarray(times, float)
    y = outputs_of(Flight(hidden).states(tags - hidden.tau))       # a late tag reads the flight earlier
    y["h"] = y["h"] + hidden.bias_h
    return y


def gps_times(seed: int):
    """The fixes received: 10 Hz from ``wren.T_GPS`` to ``wren.TF`` less 2 % lost (seeded)."""
    t = V.gps_times()
    rng = np.random.default_rng(20_000 + seed)
    return t[rng.random(t.size) >= DROPOUT_SHARE]


DROPOUT_SHARE = 0.02


def measurements(hidden: Hidden, seed: int):
    """The case's GPS log (``rocketid.Measurements`` without sigmas): noise at ``wren.SIGMA``, rounded to the
    log's resolution ``wren.RESOLUTION``."""
    import rocketid as ri
    t = gps_times(seed)
    exact = exact_outputs(hidden, t)
    rng = np.random.default_rng(seed)
    channels = []
    for name in ("x", "h", "v"):
        noisy = exact[name] + V.SIGMA[name] * rng.standard_normal(t.size)
        q = V.RESOLUTION[name]
        channels.append(ri.Channel(name, t, np.round(np.round(noisy / q) * q, 6)))
    return ri.Measurements(tuple(channels))

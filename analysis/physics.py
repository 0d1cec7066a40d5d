"""Physics helpers in SI units: Rayleigh time, the particle size classes of
the Gaussian PSD, the roller's motion, LIGGGHTS' prime seeds, the length
a fed pile of a given mass per width occupies, and the largest tolerated overlap.
"""
from __future__ import annotations

from math import pi, sqrt

import numpy as np

#: Solid fraction assumed when sizing the insertion region of the heap.
INSERTION_SOLID_FRACTION = 0.2


#: Solid fraction of a loose pile: sizes the feed zone ahead of the roller.
PILE_SOLID_FRACTION = 0.55


#: The feed zone holds this many times the fed pile's bulk volume (room for its slope and toe).
FEED_ZONE_ROOM = 2.0


#: Largest tolerated particle-particle overlap in the sampling region (what is measured), as a
#: fraction of the smaller radius: the soft-sphere contact's limit for a sound layer. The run's
#: health (:func:`analysis.dem.health.layer_health`) and the dataset's check of each run
#: (:func:`analysis.metrics.dataset.check_run`) both hold runs to it.
MAX_OVERLAP = 0.05


def rayleigh_time(radius: float, density: float, youngs_modulus: float, poisson_ratio: float) -> float:
    """Rayleigh time [s] of a sphere, as LIGGGHTS' ``check/timestep/gran`` computes it.

    ``dt_R = pi r sqrt(rho / G) / (0.1631 nu + 0.8766)``, ``G = E / (2 (1 + nu))``.
    """
    shear_modulus = youngs_modulus / (2.0 * (1.0 + poisson_ratio))
    return pi * radius * sqrt(density / shear_modulus) / (0.1631 * poisson_ratio + 0.8766)


def psd_classes(mean: float, std: float, dmin: float, dmax: float, n: int):
    """Discretise a clipped Gaussian number distribution of diameters.

    The range ``[dmin, dmax]`` is cut into ``n`` classes of equal width. A class
    is represented by the diameter whose cube is the class's mean ``d^3``
    (so each class keeps its mass), and weighted by its mass fraction.

    Returns
    -------
    diameters : ndarray (n,), same unit as the inputs
    mass_fractions : ndarray (n,), summing to 1
    """
    edges = np.linspace(dmin, dmax, n + 1)
    fine = np.linspace(dmin, dmax, 200 * n + 1)
    pdf = np.exp(-0.5 * ((fine - mean) / std) ** 2)
    which = np.clip(np.searchsorted(edges, fine, side="right") - 1, 0, n - 1)
    number = np.bincount(which, weights=pdf, minlength=n)
    third_moment = np.bincount(which, weights=pdf * fine**3, minlength=n)
    diameters = np.cbrt(third_moment / number)
    return diameters, third_moment / third_moment.sum()


def is_prime(n: int) -> bool:
    return n > 1 and all(n % k for k in range(2, int(n**0.5) + 1))


def liggghts_seeds(base: int, count: int) -> list[int]:
    """``count`` distinct primes > 10000 derived from ``base`` (LIGGGHTS' seeds)."""
    seeds, n = [], 10007 + 1009 * base
    while len(seeds) < count:
        if is_prime(n):
            seeds.append(n)
        n += 1
    return seeds


def roller_motion(speed: float, omega: float, radius: float) -> dict:
    """The LIGGGHTS moves of the roller for the paper's sign convention.

    The roller travels along +x at ``speed`` [m/s] and turns about its axis
    (along y) so that its bottom point moves at ``speed + omega * radius`` along
    +x: positive ``omega`` [rad/s] counter-rotates, negative rolls forward.
    A right-handed rotation about +y moves the bottom point along -x, so the
    rotation axis is ``-sign(omega) * y``. ``rotate`` takes a period, so
    ``omega = 0`` has no rotation at all.
    """
    motion = {"velocity": (speed, 0.0, 0.0), "rotate": None,
              "bottom_speed": speed + omega * radius}
    if omega != 0:
        motion["rotate"] = {"axis": (0.0, -float(np.sign(omega)), 0.0), "period": 2 * pi / abs(omega)}
    return motion


def number_mean_volume(diameters, mass_fractions) -> float:
    """Number-mean particle volume [m^3] of size classes weighted by mass."""
    return float(1.0 / np.sum(np.asarray(mass_fractions) / (pi / 6 * np.asarray(diameters) ** 3)))


def feed_length(pile_per_width: float, density: float, radius: float, gap: float) -> float:
    """Length [m] ahead of the roller axis of the feed zone for a pile of
    ``pile_per_width`` [kg/m of strip width].

    The zone is the wedge between the bed and the roller's front (height
    ``gap + R - sqrt(R^2 - x^2)`` at ``x`` ahead of the axis); it is made long
    enough to hold :data:`FEED_ZONE_ROOM` times the pile's bulk cross-section
    (solid fraction :data:`PILE_SOLID_FRACTION`).
    """
    x = np.linspace(0.0, 0.95 * radius, 20001)
    height = gap + radius - np.sqrt(radius**2 - x**2)
    wedge = np.concatenate([[0.0], np.cumsum(np.diff(x) * (height[1:] + height[:-1]) / 2)])
    need = FEED_ZONE_ROOM * pile_per_width / (density * PILE_SOLID_FRACTION)
    if need > wedge[-1]:
        raise ValueError(f"a pile of {pile_per_width * 1e3:.4g} mg/mm does not fit twice in the wedge ahead of the "
                         f"roller (at most {wedge[-1] * density * PILE_SOLID_FRACTION / FEED_ZONE_ROOM * 1e3:.3g})")
    return float(np.interp(need, wedge, x))


def polygon_circumradius(radius: float, facets: int) -> float:
    """Circumradius [m] of the ``facets``-gon whose bottom, averaged over a turn, is ``radius``
    below its axis.

    A polygon turning about its axis lowers its bottom from ``Rc cos(pi/n)`` (a flat facet
    down) to ``Rc`` (a vertex down); the mean over a turn is ``Rc sin(pi/n) / (pi/n)``, so a
    circumradius ``radius (pi/n) / sin(pi/n)`` keeps the roller's mean gap where it is set.
    """
    half = pi / facets
    return radius * half / np.sin(half)


def polygon_bottom_range(radius: float, facets: int) -> tuple[float, float]:
    """(nearest, farthest) [m] of the bottom of :func:`polygon_circumradius`'s polygon below
    its axis over a turn: a flat facet down, a vertex down."""
    rc = polygon_circumradius(radius, facets)
    return float(rc * np.cos(pi / facets)), float(rc)

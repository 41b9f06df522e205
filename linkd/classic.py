"""Classical mechanisms built from their link lengths: references for tests, demos and docs."""

from __future__ import annotations

import numpy as np

from linkd.mechanism import Mechanism


def place(p1: np.ndarray, p2: np.ndarray, r1: float, r2: float, side: int) -> np.ndarray:
    """The point at distance r1 from p1 and r2 from p2, left (+1) or right (-1) of p1->p2."""
    p1, p2 = np.asarray(p1, float), np.asarray(p2, float)
    d = np.linalg.norm(p2 - p1)
    a = (r1**2 - r2**2 + d**2) / (2 * d)
    h2 = r1**2 - a**2
    if h2 < 0:
        raise ValueError("the two circles do not meet")
    u = (p2 - p1) / d
    return p1 + a * u + side * np.sqrt(h2) * np.array([-u[1], u[0]])


def _four_bar(crank: float) -> Mechanism:
    """Four-bar (crank `crank`, coupler 3.5, rocker 3, ground 4) with a coupler point on a
    ternary coupler plate."""
    o, g = np.array([0.0, 0.0]), np.array([4.0, 0.0])
    m = np.array([0.0, crank])
    c = place(m, g, 3.5, 3.0, -1)
    p = place(m, c, 2.5, 2.0, 1)
    return Mechanism(
        [o, m, g, c, p], [1, 0, 1, 0, 0], [(0, 1), (1, 3), (2, 3), (1, 4), (3, 4)], (0, 1), 4
    )


def crank_rocker() -> Mechanism:
    """Grashof crank-rocker: the crank of length 1 turns fully."""
    return _four_bar(1.0)


def non_grashof_four_bar() -> Mechanism:
    """Non-Grashof four-bar: an input link of length 3 cannot turn fully."""
    return _four_bar(3.0)


JANSEN = dict(a=38, b=41.5, c=39.3, d=40.1, e=55.8, f=39.4, g=36.7, h=65.7, i=49, j=50,
              k=61.9, l=7.8, m=15)  # fmt: skip


def jansen_leg(crank_angle: float = np.pi / 2) -> Mechanism:
    """Theo Jansen's Strandbeest leg with his 'holy numbers' (lengths in mm).

    Joints: 0 crank axle, 1 crank tip, 2 frame pivot, 3 upper knee, 4 lower knee, 5 hip,
    6 shin joint, 7 foot (end effector).
    """
    L = JANSEN
    o = np.array([0.0, 0.0])
    z = np.array([-L["a"], -L["l"]])
    m = L["m"] * np.array([np.cos(crank_angle), np.sin(crank_angle)])
    upper = place(m, z, L["j"], L["b"], -1)
    lower = place(m, z, L["k"], L["c"], 1)
    hip = place(upper, z, L["e"], L["d"], -1)
    shin = place(hip, lower, L["f"], L["g"], -1)
    foot = place(shin, lower, L["h"], L["i"], -1)
    links = [(0, 1), (1, 3), (2, 3), (1, 4), (2, 4), (3, 5), (2, 5), (5, 6), (4, 6), (6, 7),
             (4, 7)]  # fmt: skip
    return Mechanism([o, m, z, upper, lower, hip, shin, foot], [1, 0, 1, 0, 0, 0, 0, 0], links,
                     (0, 1), 7)  # fmt: skip


def jansen_walker(phases: int = 1, mirrored: bool = True) -> Mechanism:
    """Jansen legs on one crank, as a Strandbeest walker is built: `phases` crank pins equally
    spaced round the axle (the crank a plate joining them; an odd number, since a pin opposite
    another lies in line with it and the axle, where no dyad holds it), one leg on each, and with
    `mirrored` a second leg on each pin, the first's mirror image on a second frame pivot.
    End effector: the first leg's foot. 8 joints for one leg; 36 for three mirrored pairs."""
    if phases < 1 or phases % 2 == 0:
        raise ValueError(f"a walker's crank needs an odd number of pins, got {phases}")
    angles = np.pi / 2 + 2 * np.pi * np.arange(phases) / phases
    flip, leg = np.array([-1.0, 1.0]), jansen_leg()
    frame = leg.positions[2]
    positions = [np.zeros(2), jansen_leg(angles[0]).positions[1], frame]
    positions += [frame * flip] if mirrored else []
    links, feet = [(0, 1)], []
    for k, angle in enumerate(angles):
        tip = 1
        if k:  # a further crank pin, fixed on the crank plate
            tip = len(positions)
            positions.append(jansen_leg(angle).positions[1])
            links += [(0, tip), (1, tip)]
        legs = [(jansen_leg(angle).positions, 2)]
        if mirrored:  # the mirror image of the leg whose crank pin is this one's mirror
            legs.append((jansen_leg(np.pi - angle).positions * flip, 3))
        for joints, pivot in legs:
            index = {0: 0, 1: tip, 2: pivot}
            for j in range(3, 8):
                index[j] = len(positions)
                positions.append(joints[j])
            links += [(index[i], index[j]) for i, j in leg.links if (i, j) != (0, 1)]
            feet.append(index[7])
    fixed = [k in (0, 2, 3 if mirrored else 2) for k in range(len(positions))]
    return Mechanism(positions, fixed, links, (0, 1), feet[0])


def _six_bar(coupler_ternary: bool) -> Mechanism:
    """Four-bar O-M-C-G, then a dyad E on a point D and a third ground pivot H, with the
    end effector F on the link D-E. D sits on the rocker (Watt) or on the coupler (Stephenson)."""
    o, g, h = np.array([0.0, 0.0]), np.array([4.0, 0.0]), np.array([6.0, 3.0])
    m = np.array([0.0, 1.0])
    c = place(m, g, 3.5, 3.0, -1)
    if coupler_ternary:
        d = place(m, c, 2.5, 2.0, 1)
        d_links = [(1, 4), (3, 4)]
    else:
        d = place(g, c, 2.0, 1.5, 1)
        d_links = [(2, 4), (3, 4)]
    e = place(d, h, 3.0, 3.0, 1)
    f = place(d, e, 2.0, 2.0, 1)
    links = [(0, 1), (1, 3), (2, 3), *d_links, (4, 6), (5, 6), (4, 7), (6, 7)]
    return Mechanism([o, m, g, c, d, h, e, f], [1, 0, 1, 0, 0, 1, 0, 0], links, (0, 1), 7)


def watt_six_bar() -> Mechanism:
    """Watt II six-bar: ternary ground and ternary rocker share a pivot."""
    return _six_bar(coupler_ternary=False)


def stephenson_six_bar() -> Mechanism:
    """Stephenson six-bar: ternary ground and ternary coupler joined only through binary links."""
    return _six_bar(coupler_ternary=True)

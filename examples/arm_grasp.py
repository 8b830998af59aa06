"""A 7-dof arm picks a cable off a table, lifts it clear, holds it, carries it over a peg and
lays it there.

Shows: a robot as MuJoCo users build one (mjcf/arm.xml: seven hinges on position servos,
gravity compensated, a two-finger hand whose second finger follows the first through a
joint equality, one finger servo) grasping a derods rod by friction alone. The arm's tree
(9 dofs) joins derods' contact solve in the steps the pads touch the cable, its finger
equality and joint limits with it (derods/sim/contact.py, derods/sim/tree_rows.py). The
hand follows a Cartesian plan: each step a few damped least-squares iterations on a
scratch copy of the model turn the plan's grip point and hand orientation into the seven
servo targets.
Expected: arm_grasp.mp4; the cable rises clear of the table, hangs still from the pads
while held, drapes over the peg when released. Printed: how far the cable crept in the
pads over the hold, how deep it went into them, how high it was lifted, where it rests
on the peg.

Run:   .venv/bin/python examples/arm_grasp.py [--out out/examples] [--dt 0.002] [--hand linkage] [--test]

``--hand linkage`` swaps the slide fingers for a parallel linkage on each side, closed
by two connect equalities and coupled by a joint equality (:func:`linkage_hand`): a tree
of 13 dofs, beyond the band's 9, which joins the solve as its border.

Measured (2026-12-05, derods' default contact settings; tests/test_arm_grasp.py): crept
0.15 / 0.06 mm over the 2 s hold at dt 2e-3 / 5e-3 (linkage 0.08 / 0.03), 0.17 / 0.14 mm
deep in a pad of r = 6 mm (linkage 0.20 / 0.14), lifted 0.40 / 0.42 m clear of the table.
With the arm's rows left to MuJoCo (its forces computed for bare vertex masses) the pads
close through the cable and nothing is lifted. With pads of MuJoCo's default priority
and solimp, derods' default contact lets the cable creep out and fall (273 mm over the
hold); ``ContactParams(static_friction=True)`` holds it (0.009 mm, 0.53 mm deep).
"""

from __future__ import annotations

import argparse
import pathlib

import mujoco
import numpy as np

import derods
from derods import World, geometry, scenes, shapes
from derods.viz import filming

#: The cable: 0.6 m, 6 mm radius, E = 2e7 Pa (a soft rubber cable), 40 edges, along x on
#: the table (top z = 0.4 m) centred at x = CABLE_X.
CABLE = dict(length=0.6, n_edges=40)
MATERIAL = derods.Material(young=2e7, radius=0.006, density=1100.0)
CABLE_X = -0.2
TABLE_TOP = 0.4
#: The peg's axis x [m] and top z [m] (mjcf/arm.xml).
PEG = (0.35, 0.55)
#: The grip point's plan (the site between the pads) [m] and how closed the fingers are
#: told to be (0 open, 1 closed: the hand's servo targets, HANDS) over time [s]:
#: (time, x, y, z, closed). Linear between the rows. The hand points down, its fingers
#: closing along y; the pads (16 mm tall) 2 mm clear of the table around the cable.
GRIP_Z = TABLE_TOP + 0.010
PLAN = np.array([
    (0.0, CABLE_X, 0.0, 0.60, 0.0),        # above the cable, fingers open
    (0.8, CABLE_X, 0.0, 0.60, 0.0),        # the cable settles
    (1.6, CABLE_X, 0.0, GRIP_Z, 0.0),      # down: pads around the cable
    (2.2, CABLE_X, 0.0, GRIP_Z, 1.0),      # close (the pads stop on the cable)
    (2.4, CABLE_X, 0.0, GRIP_Z, 1.0),
    (3.6, CABLE_X, 0.0, 0.90, 1.0),        # lift 0.49 m: clear of the table
    (5.8, CABLE_X, 0.0, 0.90, 1.0),        # hold still
    (7.0, 0.35, 0.0, 0.90, 1.0),           # carry over the peg
    (7.6, 0.35, 0.0, 0.62, 1.0),           # lower it onto the peg
    (7.9, 0.35, 0.0, 0.62, 0.0),           # open
    (8.6, 0.35, 0.0, 0.62, 0.0),           # the cable drapes over the peg
])
HOLD = (3.8, 5.8)  # lifted and still for 2 s: the cable must not creep in the pads
#: The hand's orientation over the whole plan: fingers down (hand z = -world z), closing
#: along world y.
HAND = np.array([[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]).T
#: The cable's contact settings (derods' defaults but for condim and friction).
CONTACT = derods.ContactParams()
ARM_JOINTS = ("j1", "j2", "j3", "j4", "j5", "j6", "j7")
#: The arm's posture [rad] the plan is solved from, and draws towards (bent over the table).
START = np.array([0.3, -0.4, 0.0, -1.7, 0.0, -1.0, 0.0])
#: The largest move of a joint target in one iteration of the arm's inverse kinematics [rad].
MAX_STEP = 0.2


#: The hands: the finger servo's targets open and closed (mjcf/arm.xml's slides [m]; the
#: linkage's driving hinge [rad], :func:`linkage_hand`).
HANDS = {"slide": (0.04, 0.0), "linkage": (0.0, 0.4)}
#: The linkage hand's links [m]: the driving and following links' length, their hinges'
#: offset along y, how far the hinges sit below the hand's face (+z), the pads below the
#: coupler's hinge.
LINK, LINK_GAP, LINK_BASE, PAD_DROP = 0.06, 0.015, 0.02, 0.035


def linkage_hand(spec: mujoco.MjSpec) -> None:
    """Replace arm.xml's slide fingers by a parallel linkage on each side (in ``spec``): a
    driving link hinged to the hand, a following link hinged beside it, a coupler
    carrying the pad hinged to the driver's tip and connected to the follower's (a
    parallelogram: the pad stays upright as it closes), the right driver following the
    left through a joint equality, one servo on the left driver ("fingers", [rad], 0
    open). The arm's tree grows from 9 to 13 dofs, beyond the band's 9: it joins derods'
    contact solve as the band's border, its two connects and its equality with it."""
    for e in list(spec.excludes) + list(spec.equalities):
        spec.delete(e)
    spec.delete(spec.actuator("fingers"))
    for name in ("finger_l", "finger_r"):
        spec.delete(spec.body(name))
    hand, pad = spec.body("hand"), spec.find_default("pad")
    hinge = dict(type=mujoco.mjtJoint.mjJNT_HINGE, damping=0.005, armature=0.0)  # not the arm's 2 N m s
    link = dict(type=mujoco.mjtGeom.mjGEOM_CAPSULE, size=[0.004, 0, 0], mass=0.05, contype=0, conaffinity=0)
    # the loops closed hard: MuJoCo's default equality (solref 0.02 s) on 50 g links gave way
    # by 13 mm under the squeeze and the pads tilted 9 degrees (its time constant is at
    # least 2 dt, whatever is asked)
    stiff = dict(solref=[0.004, 1.0], solimp=[0.99, 0.999, 0.001, 0.5, 2.0])
    for side, sign in (("l", 1.0), ("r", -1.0)):
        y0 = sign * 0.03  # the driver's hinge; the follower's LINK_GAP outboard
        axis = [sign, 0.0, 0.0]  # a positive angle closes either side
        driver = hand.add_body(name=f"driver_{side}", pos=[0, y0, LINK_BASE])
        driver.add_joint(name=f"drive_{side}", axis=axis, range=[0.0, 0.45], limited=True, **hinge)
        driver.add_geom(fromto=[0, 0, 0, 0, 0, LINK], **link)
        coupler = driver.add_body(name=f"coupler_{side}", pos=[0, 0, LINK])
        coupler.add_joint(name=f"couple_{side}", axis=axis, **hinge)
        coupler.add_geom(fromto=[0, 0, 0, 0, sign * LINK_GAP, 0], **link)
        coupler.add_geom(fromto=[0, 0, 0, 0, 0, PAD_DROP], **link)
        coupler.add_geom(name=f"pad_{side}", default=pad, pos=[0, -sign * 0.006, PAD_DROP])
        follower = hand.add_body(name=f"follower_{side}", pos=[0, y0 + sign * LINK_GAP, LINK_BASE])
        follower.add_joint(name=f"follow_{side}", axis=axis, **hinge)
        follower.add_geom(fromto=[0, 0, 0, 0, 0, LINK], **link)
        spec.add_equality(type=mujoco.mjtEq.mjEQ_CONNECT, name1=f"coupler_{side}", name2=f"follower_{side}",
                          objtype=mujoco.mjtObj.mjOBJ_BODY, data=[0, sign * LINK_GAP, 0] + [0] * 9, **stiff)
    spec.add_equality(type=mujoco.mjtEq.mjEQ_JOINT, name1="drive_r", name2="drive_l", objtype=mujoco.mjtObj.mjOBJ_JOINT,
                      **stiff)
    spec.add_actuator(name="fingers", target="drive_l", trntype=mujoco.mjtTrn.mjTRN_JOINT,
                      gaintype=mujoco.mjtGain.mjGAIN_FIXED, gainprm=[3.0] + [0] * 9,
                      biastype=mujoco.mjtBias.mjBIAS_AFFINE, biasprm=[0, -3.0, -0.1] + [0] * 7,
                      ctrlrange=[0.0, 0.45], ctrllimited=True, forcerange=[-0.6, 0.6], forcelimited=True)
    # the grip point between the pads once they touch a 6 mm cable (sin a = (0.02 - r) / LINK)
    closed = np.arcsin((0.02 - MATERIAL.radius) / LINK)
    spec.site("grip").pos = [0.0, 0.0, LINK_BASE + LINK * np.cos(closed) + PAD_DROP]


def plan(t: float) -> tuple[np.ndarray, float]:
    """The grip point [m] (3,) and how closed the fingers are told to be (0 .. 1) at
    time t [s]."""
    row = [float(np.interp(t, PLAN[:, 0], PLAN[:, k])) for k in range(1, 5)]
    return np.array(row[:3]), row[3]


class ArmIK:
    """Joint targets [rad] for a grip point and the hand orientation HAND: damped least
    squares on the site "grip", on a scratch copy of the model posed at the last targets
    (not at the arm's measured state, so the servos' lag does not feed back)."""

    def __init__(self, model: mujoco.MjModel, damping: float = 1e-2):
        self.m = model
        self.d = mujoco.MjData(model)
        self.site = model.site("grip").id
        self.qadr = np.array([model.joint(j).qposadr[0] for j in ARM_JOINTS])
        self.dofs = np.array([model.joint(j).dofadr[0] for j in ARM_JOINTS])
        self.q = START.copy()
        self.lam2 = damping ** 2
        self._jp = np.zeros((3, model.nv))
        self._jr = np.zeros((3, model.nv))

    def solve(self, target: np.ndarray, iterations: int = 5) -> np.ndarray:
        """The joint targets [rad] (7,) that put the grip point at target (3,) [m], the
        seventh dof's freedom spent drawing the arm towards START (its null space), each
        iteration's move at most MAX_STEP per joint."""
        m, d = self.m, self.d
        for _ in range(iterations):
            d.qpos[self.qadr] = self.q
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            rot = d.site_xmat[self.site].reshape(3, 3)
            err = np.concatenate([target - d.site_xpos[self.site],
                                  0.5 * sum(np.cross(rot[:, k], HAND[:, k]) for k in range(3))])
            mujoco.mj_jacSite(m, d, self._jp, self._jr, self.site)
            jac = np.vstack([self._jp, self._jr])[:, self.dofs]
            pinv = jac.T @ np.linalg.inv(jac @ jac.T + self.lam2 * np.eye(6))
            dq = pinv @ err + (np.eye(7) - pinv @ jac) @ (0.1 * (START - self.q))
            self.q = self.q + np.clip(dq, -MAX_STEP, MAX_STEP)
        return self.q


def build(dt: float = 2e-3, hand: str = "slide", contact: derods.ContactParams = CONTACT,
          plain_pads: bool = False) -> World:
    """The arm scene (its hand: a key of HANDS) with the cable lying on the table under the
    hand's first pose; the cable's contact settings ``contact``; ``plain_pads``: the pads
    with MuJoCo's default priority and solimp (arm.xml makes them hard and lets them win
    the mix, as robot models' pads often do)."""
    spec = mujoco.MjSpec.from_file(str(scenes.path("arm")))
    if hand == "linkage":
        linkage_hand(spec)
    if plain_pads:
        for side in ("l", "r"):
            pad = spec.geom(f"pad_{side}")
            pad.priority, pad.solimp = 0, [0.9, 0.95, 0.001, 0.5, 2.0]
    world = World(spec, dt=dt, mass_damping=1.0, contact=contact)
    x = shapes.straight(CABLE["length"], CABLE["n_edges"])
    x -= x.mean(axis=0)
    x += (CABLE_X, 0.0, TABLE_TOP + MATERIAL.radius + 1e-4)
    world.add_rod(derods.Rod(x, MATERIAL), "cable", rgba=(0.85, 0.35, 0.15, 1))
    world.compile()
    return world


class Grasp:
    """Drives the arm through PLAN and measures: the cable's creep in the pads over HOLD
    (how far the point between the pads moved along the cable), the deepest contact in a
    pad, and how high the cable's lowest vertex was lifted above the table."""

    def __init__(self, world: World, hand: str = "slide"):
        m, d = world.model, world.data
        self.open, self.closed = HANDS[hand]
        self.ik = ArmIK(m)
        self.act = np.array([m.actuator(j).id for j in ARM_JOINTS])
        self.fingers = m.actuator("fingers").id
        self.qadr = self.ik.qadr
        d.qpos[self.qadr] = START
        d.qpos[self.qadr] = self.ik.solve(plan(0.0)[0], iterations=60)  # start at the plan
        d.ctrl[self.act] = d.qpos[self.qadr]
        mujoco.mj_forward(m, d)
        self.pad_ids = (m.geom("pad_l").id, m.geom("pad_r").id)
        self.pads = set(self.pad_ids)
        self.grip_along, self.depth, self.lowest = [], [], []

    def __call__(self, world: World) -> None:
        """Before each step: measure what the last step left, then set the targets."""
        self.measure(world)
        target, closed = plan(world.time + world.model.opt.timestep)
        d = world.data
        d.ctrl[self.act] = self.ik.solve(target)
        d.ctrl[self.fingers] = self.open + closed * (self.closed - self.open)

    def measure(self, world: World) -> None:
        d, t = world.data, world.time
        if HOLD[0] <= t <= HOLD[1]:
            x = world.positions("cable")
            mid = 0.5 * (d.geom_xpos[self.pad_ids[0]] + d.geom_xpos[self.pad_ids[1]])
            self.grip_along.append(geometry.arc_length_to(x, mid))
            self.lowest.append(float(x[:, 2].min()) - (TABLE_TOP + MATERIAL.radius))
            for c in d.contact[: d.ncon]:
                if set(c.geom) & self.pads:
                    self.depth.append(-c.dist)

    def summary(self) -> dict:
        """creep [m] over the hold, depth [m] into a pad, lifted [m]: the lowest vertex's
        least height over the table (resting: 0) while held."""
        return {"creep": float(np.ptp(self.grip_along)) if self.grip_along else np.inf,
                "depth": max(self.depth, default=0.0),
                "lifted": min(self.lowest, default=0.0)}


def run(dt: float = 2e-3, seconds: float | None = None, out: pathlib.Path | None = None,
        size=(1280, 720), hand: str = "slide", **scene) -> dict:
    """Run the plan (``seconds``: all of it by default) at step dt [s] with ``hand`` (a key
    of HANDS; ``scene``: :func:`build`'s contact and plain_pads), filming to ``out`` if
    given. Returns :meth:`Grasp.summary`, the cable's vertices at the end and the arm's
    tree's dofs."""
    world = build(dt, hand, **scene)
    grasp = Grasp(world, hand)
    seconds = float(PLAN[-1, 0]) if seconds is None else seconds
    filming.step_or_film(world, seconds, grasp, out, size)
    result = grasp.summary()
    result["cable"] = world.positions("cable").copy()
    result["tree_dofs"] = int(world.model.tree_dofnum[world.model.body_treeid[world.model.body("hand").id]])
    return result


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/examples", help="output folder (created)")
    ap.add_argument("--dt", type=float, default=2e-3, help="step [s] (default 2e-3)")
    ap.add_argument("--hand", choices=sorted(HANDS), default="slide",
                    help="slide fingers (9-dof tree, default) or a parallel linkage (13 dofs)")
    ap.add_argument("--test", action="store_true", help="a small video, for CI")
    args = ap.parse_args(argv)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    size = (320, 180) if args.test else (1280, 720)
    name = "arm_grasp.mp4" if args.hand == "slide" else f"arm_grasp_{args.hand}.mp4"
    s = run(args.dt, out=out / name, size=size, hand=args.hand)
    x = s["cable"]
    on_peg = x[np.argmin(np.abs(x[:, 0] - PEG[0])), 2]
    print(f"wrote {out / name} ({s['tree_dofs']}-dof tree): crept {s['creep'] * 1e3:.2f} mm in the pads over the "
          f"{HOLD[1] - HOLD[0]:.1f} s hold, deepest in a pad {s['depth'] * 1e3:.2f} mm (r = "
          f"{MATERIAL.radius * 1e3:.0f} mm), lifted {s['lifted'] * 1e3:.0f} mm clear of the table; it rests on "
          f"the peg at z = {on_peg:.4f} m (peg top + r = {PEG[1] + MATERIAL.radius:.4f} m)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

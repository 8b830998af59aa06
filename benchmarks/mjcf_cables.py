"""The cable models of mjcf/cables/ run three ways, settled, compared (docs/mjcf.md's table).

    python benchmarks/mjcf_cables.py            # MuJoCo 4: derods (and MuJoCo 4's own flex)
                                                # plus MuJoCo 3.17 with the cable plugin
                                                # through .venv317/bin/python (or $PYTHON317)

Each static model is settled (run until its vertices move less than SETTLED m/s, at most
its own time limit) by derods on MuJoCo 4 (``World(path)``) and by MuJoCo 3.17 running the
same file with the cable plugin, and the vertex positions compared: the largest distance
between corresponding vertices as a share of the rod's length. Where the plugin is known to
be inaccurate (its clamp acts one edge out, tests317), both are also compared with the
closed form: a cantilever's tip sag q L'^4 / (8 E I) (L' from the middle of the clamped
edge), a pinned span's mid sag 5 q L^4 / (384 E I), a twisted end's angle T L' / (G J).
``--plugin-only`` is the 3.17 half, printing JSON (run by the other half).
"""

from __future__ import annotations

import json
import math
import os
import pathlib
import subprocess
import sys

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
MODELS = ROOT / "mjcf" / "cables"
#: Settled: no vertex faster than this [m/s].
SETTLED = 1e-4
#: The settling test's window [s] (a frame turning counts at 0.1 m per unit of its matrix).
WINDOW = 0.05
#: name: (seconds at most, ctrl, the composites' prefixes)
STATIC = {
    "s_curve_slider": (6.0, None, [""]),
    "two_cables": (4.0, None, ["a", "b"]),
    "ball_pinned": (6.0, None, [""]),
    "belt_motor": (4.0, [0.002], ["belt"]),
}
G = 9.81


def plugin_shapes() -> dict:
    """MuJoCo 3.17 with the cable plugin: each static model settled, its vertices (the chain
    bodies' origins and S_last) and the last body's turn about its tangent [rad]."""
    import mujoco

    out = {}
    for name, (seconds, ctrl, prefixes) in STATIC.items():
        m = mujoco.MjModel.from_xml_path(str(MODELS / f"{name}.xml"))
        d = mujoco.MjData(m)
        if ctrl is not None:
            d.ctrl[:] = ctrl
        mujoco.mj_forward(m, d)
        r0 = {p: d.xmat[m.body(f"{p}B_last").id].reshape(3, 3).copy() for p in prefixes}
        t, settled, before = 0.0, False, None
        while t < seconds:
            for _ in range(int(round(WINDOW / m.opt.timestep))):
                mujoco.mj_step(m, d)
            t = d.time
            now = np.concatenate([d.xpos.ravel(), d.xmat.ravel() * 0.1])
            if before is not None and t > 0.5 and np.max(np.abs(now - before)) / WINDOW < SETTLED:
                settled = True
                break
            before = now
        rods = {}
        for p in prefixes:
            ids = [m.body(f"{p}B_first").id]
            while m.body(ids[-1]).name != f"{p}B_last":
                ids.append(int(np.flatnonzero(m.body_parentid == ids[-1])[0]))
            x = np.vstack([d.xpos[ids], d.site_xpos[m.site(f"{p}S_last").id]])
            rel = r0[p].T @ d.xmat[ids[-1]].reshape(3, 3)
            rods[p] = {"x": x.tolist(), "turn": math.atan2(rel[2, 1], rel[1, 1])}
        out[name] = {"rods": rods, "t": t, "settled": settled, "version": mujoco.__version__}
    return out


def derods_shapes() -> dict:
    """derods on MuJoCo 4: the same, and the world's rods' materials."""
    import warnings

    from derods import World

    warnings.simplefilter("ignore")
    out = {}
    for name, (seconds, ctrl, prefixes) in STATIC.items():
        w = World(str(MODELS / f"{name}.xml"))
        w.compile()
        if ctrl is not None:
            w.data.ctrl[:] = ctrl
        r0 = {p: w.data.xmat[w.model.body(f"{p}B_last").id].reshape(3, 3).copy() for p in prefixes
              if w._entries[w.rod_names.index(f"{p}cable")].end_body == f"{p}B_last"}
        settled, before = False, None
        while w.time < seconds:
            w.step(int(round(WINDOW / w.model.opt.timestep)))
            now = np.concatenate([w.all_positions().ravel(), w.data.xmat.ravel() * 0.1])
            if before is not None and w.time > 0.5 and np.max(np.abs(now - before)) / WINDOW < SETTLED:
                settled = True
                break
            before = now
        rods = {}
        for p in prefixes:
            rod = w.rods[w.rod_names.index(f"{p}cable")]
            turn = None
            if p in r0:
                rel = r0[p].T @ w.data.xmat[w.model.body(f"{p}B_last").id].reshape(3, 3)
                turn = math.atan2(rel[2, 1], rel[1, 1])
            mat = rod.material
            rods[p] = {"x": w.positions(f"{p}cable").tolist(), "turn": turn, "q": mat.line_density * G,
                       "EI": mat.alpha, "GJ": mat.beta, "L": float(rod.length), "edge": float(rod.rest_len[0])}
        out[name] = {"rods": rods, "t": w.time, "settled": settled, "dt": w.model.opt.timestep}
    return out


def flexcomp_rows() -> list:
    """The 1D flexcomp cantilever: derods (rods_from="flexcomp") and MuJoCo 4's own rod."""
    import warnings

    import mujoco

    from derods import World

    warnings.simplefilter("ignore")
    path = str(MODELS / "flexcomp_cable.xml")
    w = World(path, rods_from="flexcomp")
    w.compile()
    while w.time < 4.0:
        w.step(10)
        if w.time > 0.5 and np.max(np.abs(w.velocities("rope"))) < SETTLED:
            break
    rod = w.rods[0]
    x = w.positions("rope")
    m = mujoco.MjModel.from_xml_path(path)
    m.opt.integrator = mujoco.mjtIntegrator.mjINT_DISCRETE  # what MuJoCo recommends for its rods
    d = mujoco.MjData(m)
    ok, steps = True, 0
    while steps * m.opt.timestep < 4.0 and ok:
        mujoco.mj_step(m, d)  # (MuJoCo resets the data where it finds a bad acceleration)
        steps += 1
        ok = d.warning[int(mujoco.mjtWarning.mjWARN_BADQACC)].number == 0
    f = 0
    xm = d.flexvert_xpos[m.flex_vertadr[f]:m.flex_vertadr[f] + m.flex_vertnum[f]]
    lp = rod.length - 0.5 * rod.rest_len[0]
    w_cf = rod.material.line_density * G * lp ** 4 / (8 * rod.material.alpha)
    sag_d = x[0, 2] - x[-1, 2]
    sag_m = xm[0, 2] - xm[-1, 2] if ok else math.nan
    who = f"MuJoCo {mujoco.__version__}'s flex (discrete integrator)" + ("" if ok else f" (unstable at t = {steps * m.opt.timestep:.3g} s)")
    return [("flexcomp_cable", "tip sag, cantilever", w_cf, sag_d, sag_m, who)]


def closed_forms(der: dict, plug: dict) -> list:
    """(model, quantity, closed form, derods, plugin) rows."""
    rows = []
    for p in ("a", "b"):
        r = der["two_cables"]["rods"][p]
        lp = r["L"] - 0.5 * r["edge"]
        cf = r["q"] * lp ** 4 / (8 * r["EI"])
        xd = np.array(r["x"])
        xp = np.array(plug["two_cables"]["rods"][p]["x"])
        rows.append((f"two_cables {p}", "tip sag, cantilever", cf, xd[0, 2] - xd[-1, 2], xp[0, 2] - xp[-1, 2], "3.17 plugin"))
    r = der["ball_pinned"]["rods"][""]
    cf = 5 * r["q"] * r["L"] ** 4 / (384 * r["EI"])
    xd, xp = np.array(r["x"]), np.array(plug["ball_pinned"]["rods"][""]["x"])
    k = len(xd) // 2
    rows.append(("ball_pinned", "mid-span sag, pinned-pinned", cf, xd[0, 2] - xd[k, 2], xp[0, 2] - xp[k, 2], "3.17 plugin"))
    r = der["belt_motor"]["rods"]["belt"]
    torque = STATIC["belt_motor"][1][0]
    cf = torque * (r["L"] - r["edge"]) / r["GJ"]
    rows.append(("belt_motor", "end turn [rad], T L'/(G J)", cf, r["turn"], plug["belt_motor"]["rods"]["belt"]["turn"],
                 "3.17 plugin"))
    return rows


def main() -> int:
    if "--plugin-only" in sys.argv:
        print(json.dumps(plugin_shapes()))
        return 0
    py317 = os.environ.get("PYTHON317", str(ROOT / ".venv317" / "bin" / "python"))
    if not pathlib.Path(py317).exists():
        py317 = "/work/main/.venv317/bin/python"
    run = subprocess.run([py317, __file__, "--plugin-only"], capture_output=True, text=True, check=True)
    plug = json.loads(run.stdout.strip().splitlines()[-1])
    der = derods_shapes()
    print("| model | rod | length [m] | largest vertex distance, derods vs 3.17 plugin [share of length] | "
          "settled (derods / plugin) |")
    print("|---|---|---|---|---|")
    for name, (_, _, prefixes) in STATIC.items():
        for p in prefixes:
            xd = np.array(der[name]["rods"][p]["x"])
            xp = np.array(plug[name]["rods"][p]["x"])
            length = der[name]["rods"][p]["L"]
            gap = np.max(np.linalg.norm(xd - xp, axis=1)) / length
            print(f"| {name} | {p or '(no prefix)'} | {length:.3g} | {100 * gap:.3f} % | "
                  f"{der[name]['t']:.2f} s{'' if der[name]['settled'] else ' (not yet)'} / "
                  f"{plug[name]['t']:.2f} s{'' if plug[name]['settled'] else ' (not yet)'} |")
    print()
    print("| model | quantity | closed form | derods (error) | other (error) | other |")
    print("|---|---|---|---|---|---|")
    for model, what, cf, dv, ov, other in closed_forms(der, plug) + flexcomp_rows():
        print(f"| {model} | {what} | {cf:.5g} | {dv:.5g} ({100 * (dv / cf - 1):+.2f} %) | "
              f"{ov:.5g} ({100 * (ov / cf - 1):+.2f} %) | {other} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Divergence: how a step that lost the solution is recognised and reported.

Shared by derods' :class:`~derods.sim.world.World` and MuJoCo's native rods in the
comparison harness, so that every backend fails by the same rules: an edge
stretched beyond :data:`MAX_STRAIN`, a vertex faster than :data:`MAX_SPEED` or
not finite, or MuJoCo's bad-acceleration reset (``mjWARN_BADQACC``). The error
names the step, the rod and a fix that fits the cause: a smaller step only when the
step is the cause, the initial shape when a rod started stretched between its holds.

A World's steps run under a :class:`Guard`: before each step it refuses non-finite
values in what MuJoCo will read (a NaN written into ``data.qvel`` would make MuJoCo
reset the whole world to its start and carry on), and after it turns any MuJoCo
warning into a :class:`DivergenceError`, with the world put back where the step began.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

#: Divergence thresholds: an edge stretched beyond this strain, or a vertex faster
#: than this [m/s], means the step has lost the solution.
MAX_STRAIN = 0.5
MAX_SPEED = 1e3


class DivergenceError(RuntimeError):
    """The simulation lost the solution; the message names the step, the rod and a fix.

    step: the step whose result was found lost (None: not known)."""

    def __init__(self, message: str, step: int | None = None):
        super().__init__(message)
        self.step = step


class Diagnosis:
    """Raises :class:`DivergenceError` with the step, the rod and what to change.

    names: rod names, by index. dt [s], mode, mass_damping [1/s]: what the hint suggests
    changing (None for a backend without these knobs). initial_strain: rods held at
    both ends that start longer than their rest length, by index: their relative excess
    length (a stiff rod then springs back hard, whatever the step).
    """

    def __init__(self, names, dt: float | None = None, mode: str | None = None,
                 mass_damping: float | None = None, initial_strain: dict | None = None):
        self.names = list(names)
        self.dt, self.mode, self.mass_damping = dt, mode, mass_damping
        self.initial_strain = dict(initial_strain or {})

    def who(self, rod: int | None) -> str:
        if rod is None:
            return f"rod '{self.names[0]}'" if len(self.names) == 1 else "a rod"
        return f"rod '{self.names[rod]}'"

    def hint(self, rod: int | None) -> str:
        """What to change, for the cause derods can see: a rod started stretched between its
        holds (its initial shape), else the step (dt, mode, damping)."""
        strained = [rod] if rod in self.initial_strain else ([] if rod is not None else list(self.initial_strain))
        if strained:
            i = strained[0]
            return (f"; rod '{self.names[i]}' is held at both ends and started {100 * self.initial_strain[i]:.3g} % "
                    "longer than its rest length: start it at its rest shape (add_rod's x), hold one end only, or "
                    "give it a rest shape as long as x")
        if self.dt is None:
            return ""
        return (f"; try a smaller dt (now {self.dt:g} s)"
                + ("" if self.mode in (None, "implicit") else ", mode='implicit'")
                + (f", or more damping (mass_damping now {self.mass_damping:g} 1/s)"
                   if self.mass_damping is not None else ""))

    def _fail(self, rod: int | None, what: str, step: int, time: float):
        raise DivergenceError(f"{self.who(rod)} diverged at step {step} (t = {time:.6g} s): {what}{self.hint(rod)}",
                              step)

    def strain(self, rod: int, strain: float, step: int, time: float):
        self._fail(rod, f"edge strain {strain:.3g} exceeds {MAX_STRAIN:g}", step, time)

    def projection(self, rod: int, max_iter: int, step: int, time: float):
        self._fail(rod, f"projecting its edges back to their rest lengths did not converge in {max_iter} "
                        "iterations", step, time)

    def badqacc(self, step: int, time: float):
        self._fail(None, "MuJoCo reported bad accelerations (BADQACC) and reset the state", step, time)

    def not_positive_definite(self, what: str, step: int, time: float):
        cause = "" if self.initial_strain else (": the rods' stiffness is out of proportion to their masses (check "
                                                "young, radius, density)")
        self._fail(None, f"the implicit system is not positive definite ({what}){cause}", step, time)

    def speed(self, rod: int, velocity: float, step: int, time: float):
        if not np.isfinite(velocity):
            self._fail(rod, "NaN or infinite state", step, time)
        self._fail(rod, f"vertex speed {abs(velocity):.3g} m/s exceeds {MAX_SPEED:g}", step, time)


def check_mujoco(data: mujoco.MjData, dofs: np.ndarray, badqacc_seen: int, diagnosis: Diagnosis,
                 step: int) -> int:
    """Raise if MuJoCo reset the state or a dof in ``dofs`` is not finite or too fast; returns
    the BADQACC count to compare against next time (a backend that is plain MuJoCo)."""
    n_bad = int(data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number)
    if n_bad != badqacc_seen:
        diagnosis.badqacc(step, data.time)
    v = data.qvel[dofs]
    if len(v) and not np.max(np.abs(v)) <= MAX_SPEED:
        k = int(np.flatnonzero(~np.isfinite(v))[0]) if not np.all(np.isfinite(v)) else int(np.argmax(np.abs(v)))
        diagnosis.speed(0, float(v[k]), step, data.time)
    return n_bad


#: MuJoCo's warnings a step can raise, in words (each stops a World's step: the first
#: three would make MuJoCo reset the data to the model's start).
STEP_WARNINGS = {
    mujoco.mjtWarning.mjWARN_BADQPOS: "a NaN, infinite or huge position (BADQPOS)",
    mujoco.mjtWarning.mjWARN_BADQVEL: "a NaN, infinite or huge velocity (BADQVEL)",
    mujoco.mjtWarning.mjWARN_BADQACC: "a NaN, infinite or huge acceleration (BADQACC)",
    mujoco.mjtWarning.mjWARN_BADCTRL: "a NaN, infinite or huge control (BADCTRL)",
    mujoco.mjtWarning.mjWARN_CONTACTFULL: "more contacts than its memory holds (CONTACTFULL)",
    mujoco.mjtWarning.mjWARN_CNSTRFULL: "more constraints than its memory holds (CNSTRFULL)",
}
#: The warnings of a full arena: the step ran out of memory, it did not lose the solution.
FULL_WARNINGS = (mujoco.mjtWarning.mjWARN_CONTACTFULL, mujoco.mjtWarning.mjWARN_CNSTRFULL)
#: MuJoCo's bound on positions, velocities, accelerations and controls (mjMAXVAL):
#: beyond it a value is "huge", and MuJoCo resets the data.
MAX_VALUE = 1e10


class Guard:
    """Keeps the state each step of a World begins from, and stops a step that loses it.

    model, data: MuJoCo's. layout: where the rods live (:class:`derods.sim.layout.Layout`).
    step: the mode's step (its ``carried()`` arrays and ``carried_flags`` are saved with
    MuJoCo's state).
    diagnosis: the world's :class:`Diagnosis` (rod names, hints).

    MuJoCo's automatic reset is turned off (``mjDSBL_AUTORESET``): MuJoCo only counts its
    warnings, and a step that raised one, or that derods found lost, is undone from the
    saved state, with nothing the user set (controls, applied forces, mocap poses) lost.
    A NaN, infinite or huge value written into what MuJoCo reads (qpos, qvel, ctrl,
    qfrc_applied, xfrc_applied ...) always makes the step fail so (MuJoCo warns of it, or
    derods' solve does); the arrays are then searched for it, and it is named as the
    cause. The arrays a step may ignore (controls, activations, forces on bodies without
    dofs, mocap poses) are looked at before every step. Per step: a copy of the state, a
    dot product per array looked at, the warning counters compared.
    """

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, layout, step, diagnosis: Diagnosis):
        self.model, self.data, self.layout, self.step, self.diagnosis = model, data, layout, step, diagnosis
        # (A MuJoCo without the flag resets by itself: the saved state is put back all the same.)
        model.opt.disableflags |= int(getattr(mujoco.mjtDisableBit, "mjDSBL_AUTORESET", 0))
        flat = lambda a: a.reshape(-1)  # noqa: E731 - views of MuJoCo's buffers
        # What MuJoCo reads in a step, with the bound beyond which MuJoCo would reset (or,
        # for forces and mocap poses, compute a NaN acceleration from it).
        self.inputs = [(name, a, bound) for name, a, bound in (
            ("qpos", data.qpos, MAX_VALUE), ("qvel", data.qvel, MAX_VALUE), ("act", data.act, MAX_VALUE),
            ("ctrl", data.ctrl, MAX_VALUE), ("qfrc_applied", data.qfrc_applied, math.inf),
            ("xfrc_applied", flat(data.xfrc_applied), math.inf), ("mocap_pos", flat(data.mocap_pos), math.inf),
            ("mocap_quat", flat(data.mocap_quat), math.inf)) if a.size]
        # One dot product per array: a . a <= bound^2 (finite, for unbounded arrays) holds
        # when every entry is finite and within bound.
        self.ahead = [(name, a, _dot_bound(bound)) for name, a, bound in self.inputs
                      if name in ("act", "ctrl", "xfrc_applied", "mocap_pos", "mocap_quat")]
        self.qvel, self.qvel_bound = data.qvel, _dot_bound(MAX_VALUE)
        # The state before this step and before the last one (derods finds an edge
        # strained beyond MAX_STRAIN at the start of the step after the one that strained it).
        self.state = [a for a in (data.qpos, data.qvel, data.act, data.qacc_warmstart) if a.size] + step.carried()
        self.flat = [a.reshape(-1) for a in self.state]  # views: saved by one concatenate
        self.saved = [_Saved(self.state) for _ in range(2)]
        # Where the inputs a step changes are in the saved state (the step began from them):
        # qpos, qvel, act, and qfrc_applied where the rods' reactions on their holders go.
        self.in_state = {name: i for name, a, _ in self.inputs for i, b in enumerate(self.state)
                         if name in ("qpos", "qvel", "act", "qfrc_applied") and a.shape == b.shape
                         and np.shares_memory(a, b)}
        # Otherwise derods writes qfrc_applied of the rod dofs only: a user's value there is
        # overwritten before MuJoCo reads it.
        self.not_rod_dofs = np.flatnonzero(layout.local_of_dof < 0)
        self.current = 0
        self.counts = data.warning.number
        self.saved_counts = self.counts.tobytes()
        # Which rod vertex each qpos entry and each body is (-1: not a rod's).
        self.vertex_of_qpos = np.full(model.nq, -1, dtype=np.int64)
        for k in range(3):
            self.vertex_of_qpos[layout.qpos_adr + k] = layout.free_vertex
        self.vertex_of_body = np.full(model.nbody, -1, dtype=np.int64)
        self.vertex_of_body[layout.body] = np.arange(len(layout.body))

    # -- around a step -----------------------------------------------------------------
    def before(self) -> None:
        """Refuse a bad control, activation, body force or mocap pose (a step may not
        notice one); save the state."""
        for name, a, dot_bound in self.ahead:
            if not _squares(a) <= dot_bound:
                bad = self._bad_input()
                if bad is not None:  # (else only the dot product overflowed)
                    self._written(bad, False)
        self.current ^= 1
        saved = self.saved[self.current]
        np.concatenate(self.flat, out=saved.buf)
        saved.time, saved.n_steps = self.data.time, self.step.n_steps
        for k in self.step.carried_flags:
            saved.flags[k] = getattr(self.step, k)
        self.saved_counts = self.counts.tobytes()

    def after(self) -> None:
        """Stop if the step raised a MuJoCo warning or left a velocity NaN or huge (a
        position goes bad only through its velocity)."""
        if self.counts.tobytes() != self.saved_counts or not _squares(self.qvel) <= self.qvel_bound:
            self.failed(None)

    def failed(self, err: Exception | None) -> None:
        """The step failed (``err``: what derods' step raised, or None): put the world back
        where the step began (or, for a state the last step left and this one found lost,
        where that one began) and raise the cause that can be seen: a bad value written
        between steps, MuJoCo's warning, derods' own finding, a velocity gone bad."""
        cur, last = self.saved[self.current], self.saved[self.current ^ 1]
        written = self._bad_input(cur)
        if written is not None:
            self.restore(cur)
            self._written(written, True, err)
        step, time = cur.n_steps + 1, self.data.time
        now = np.frombuffer(self.saved_counts, dtype=self.counts.dtype)
        raised = [w for w in STEP_WARNINGS if self.counts[w] > now[w]]
        info = int(self.data.warning[raised[0]].lastinfo) if raised else -1
        qvel_bad = self._bad(self.qvel, MAX_VALUE)
        found = getattr(err, "step", None)
        back = (isinstance(err, DivergenceError) and not raised and found == cur.n_steps
                and last.n_steps == cur.n_steps - 1)
        saved = self.restore(last if back else cur)
        if raised:
            w = raised[0]
            where = None
            if w == mujoco.mjtWarning.mjWARN_BADQPOS:
                where = self._where("qpos", info)
            elif w in (mujoco.mjtWarning.mjWARN_BADQVEL, mujoco.mjtWarning.mjWARN_BADQACC):
                where = self._where_dof(info)
            at = "" if where is None else f" at {where[1]}"
            if w in FULL_WARNINGS:  # not a lost solution: MuJoCo's arena is too small
                msg = (f"the world stopped at step {step} (t = {time:.6g} s): MuJoCo found {STEP_WARNINGS[w]}"
                       f"{self._memory_hint()}")
            else:
                msg = (f"{self._who(where)} diverged at step {step} (t = {time:.6g} s): MuJoCo found "
                       f"{STEP_WARNINGS[w]}{at}{self._hint(where)}")
        elif isinstance(err, DivergenceError):
            msg = str(err)
        elif err is not None:
            raise err  # not a lost solution: the world is back where the step began
        elif qvel_bad is not None:
            k, value = qvel_bad
            where = self._where("qvel", k)
            place = f" ({where[1]})" if where is not None else ""
            msg = (f"{self._who(where)} diverged at step {step} (t = {time:.6g} s): the step left data.qvel[{k}]"
                   f"{place} = {value!r}{self._hint(where)}")
        else:
            names = [mujoco.mjtWarning(w).name for w in range(len(now)) if self.counts[w] != now[w]]
            msg = f"the world diverged at step {step} (t = {time:.6g} s): MuJoCo warned {names}{self._hint(None)}"
        raise DivergenceError(msg + f". The world is back at its state before step {saved.n_steps + 1} "
                              f"(t = {saved.time:.6g} s)", found if found is not None else step) from err

    def restore(self, saved: "_Saved | None" = None) -> "_Saved":
        """Put back a saved state (default: the one before this step), MuJoCo's and what
        the mode carries; returns it. The other one is then forgotten."""
        saved = saved or self.saved[self.current]
        for a, b in zip(self.state, saved.arrays):
            np.copyto(a, b)
        self.data.time = saved.time
        self.step.n_steps = saved.n_steps
        for k, v in saved.flags.items():
            setattr(self.step, k, v)
        for other in self.saved:
            if other is not saved:
                other.n_steps = -2
        if self._bad_input() is None:
            mujoco.mj_forward(self.model, self.data)
        return saved

    # -- naming what is wrong ------------------------------------------------------------
    @staticmethod
    def _bad(a: np.ndarray, bound: float) -> tuple[int, float] | None:
        """The first entry of ``a`` that is not finite or beyond ``bound``: (index, value)."""
        bad = np.flatnonzero(~np.isfinite(a) | (np.abs(a) > bound))
        return (int(bad[0]), float(a[bad[0]])) if len(bad) else None

    def _bad_input(self, saved: "_Saved | None" = None) -> tuple[str, int, float] | None:
        """The first bad entry of what MuJoCo reads: (array name, index, value), or None;
        with ``saved``, as the step that began from it read them."""
        for name, a, bound in self.inputs:
            if saved is not None and name in self.in_state:
                a = saved.arrays[self.in_state[name]]
            elif name == "qfrc_applied":
                bad = self._bad(a[self.not_rod_dofs], bound)
                if bad is not None:
                    return (name, int(self.not_rod_dofs[bad[0]]), bad[1])
                continue
            bad = self._bad(a, bound)
            if bad is not None:
                return (name, *bad)
        return None

    def _written(self, bad: tuple[str, int, float], stepped: bool, err: Exception | None = None) -> None:
        """Raise naming a bad value written between steps."""
        name, k, value = bad
        where = self._where(name, k)
        place = f" ({where[1]})" if where is not None else ""
        n = self.step.n_steps + 1
        done = (f"the step was undone: the world is back at its state before step {n}" if stepped
                else "nothing was stepped")
        raise DivergenceError(
            f"data.{name}[{k}]{place} is {value!r} before step {n} (t = {self.data.time:.6g} s): a value written "
            f"between steps that MuJoCo cannot integrate (with its automatic reset it would restart the whole world "
            f"from its start); {done}: write a finite value"
            + (" (World.set_positions / set_velocities for a rod)" if where and where[0] is not None else "")
            + " and step again", n) from err

    def _memory_hint(self) -> str:
        """What to do when MuJoCo's arena cannot hold a step's contacts or constraint rows:
        give the model more memory (a guess: twice what it has)."""
        size = int(self.model.narena)
        more = f"{-(-2 * size // (1 << 20))}M" if size >= 1 << 19 else f"{-(-2 * size // 1024)}K"
        return (f": its arena of {size} bytes (model.narena) is full, the step's contacts and constraint rows live "
                f"there. Give the scene more memory: <size memory=\"{more}\"/> in its MJCF (spec.memory for an "
                "MjSpec scene); contact margins, speculative contacts and many touching rods make more rows")

    def _hint(self, where) -> str:
        """The fix: a scene element's own inputs when it is what failed (a rod's step did
        not), else the diagnosis' hint for the rod (its initial shape, or the step)."""
        if where is not None and where[0] is None:
            return (f"; {where[1]} is not a rod's: check the forces, controls and motion given to it "
                    "(data.xfrc_applied, qfrc_applied, ctrl, mocap) and its mass")
        return self.diagnosis.hint(None if where is None else where[0])

    def _who(self, where) -> str:
        """Who diverged: the rod, or the world when the place is a scene body's."""
        if where is not None and where[0] is None:
            return "the world"
        return self.diagnosis.who(None if where is None else where[0])

    def _vertex(self, v: int, axis: str = "") -> tuple[int, str]:
        lay = self.layout
        i = int(np.searchsorted(lay.v_off, v, side="right") - 1)
        return i, f"rod '{lay.names[i]}', vertex {v - int(lay.v_off[i])}" + (f", {axis}" if axis else "")

    def _where_dof(self, dof: int) -> tuple[int | None, str] | None:
        if not 0 <= dof < self.model.nv:
            return None
        local = int(self.layout.local_of_dof[dof])
        if local >= 0:
            return self._vertex(int(self.layout.free_vertex[local // 3]), "xyz"[local % 3])
        jnt = int(self.model.dof_jntid[dof])
        return None, f"dof {dof}, joint '{self.model.joint(jnt).name or jnt}'"

    def _where(self, name: str, k: int) -> tuple[int | None, str] | None:
        """(rod or None, words) for entry k of data's array ``name``."""
        m = self.model
        if name == "qpos":
            v = int(self.vertex_of_qpos[k])
            if v >= 0:
                return self._vertex(v, "xyz"[(k - int(self.layout.qpos_adr[self.layout.place[v]])) % 3])
            jnt = int(np.searchsorted(m.jnt_qposadr, k, side="right") - 1)
            return None, f"joint '{m.joint(jnt).name or jnt}'"
        if name in ("qvel", "qfrc_applied"):
            return self._where_dof(k)
        if name == "xfrc_applied":
            body = k // 6
            v = int(self.vertex_of_body[body])
            if v >= 0:
                return self._vertex(v, ("force x", "force y", "force z", "torque x", "torque y", "torque z")[k % 6])
            return None, f"body '{m.body(body).name or body}'"
        if name in ("ctrl", "act"):
            act = k if name == "ctrl" else int(np.flatnonzero(m.actuator_actadr == k)[0])
            return None, f"actuator '{m.actuator(act).name or act}'"
        if name in ("mocap_pos", "mocap_quat"):
            mocap = k // (3 if name == "mocap_pos" else 4)
            body = int(np.flatnonzero(m.body_mocapid == mocap)[0])
            return None, f"mocap body '{m.body(body).name or body}'"
        return None


#: Entries beyond which OpenBLAS computes a dot product on its threads (measured: 10 001
#: entries and up kept its threads busy).
THREADED_DOT = 10_000


def _squares(a: np.ndarray) -> float:
    """a . a, on this thread: np.dot of a long vector (a hair's qvel, 96 000 dofs) runs on
    OpenBLAS's threads, which then spin for milliseconds on the other cores and took them
    from the rods' threads (derods._numba.parallel: each of a hair's two chunks of the rod
    step took 17 ms instead of 9). einsum's own loop does not, but costs ~0.8 us more a
    call: a short vector keeps np.dot."""
    return np.dot(a, a) if a.size <= THREADED_DOT else np.einsum("i,i->", a, a)


def _dot_bound(bound: float) -> float:
    """What a . a may reach when every entry of a is within ``bound`` (finite, if unbounded)."""
    return bound * bound if bound < math.inf else float(np.finfo(float).max)


class _Saved:
    """A copy of a world's state: its arrays (MuJoCo's qpos, qvel, act, warm start and what
    the mode carries) laid end to end in ``buf``, time [s] and the step count."""

    def __init__(self, state: list):
        self.buf = np.concatenate([a.reshape(-1) for a in state])
        ends = np.cumsum([a.size for a in state])
        self.arrays = [self.buf[e - a.size:e].reshape(a.shape) for a, e in zip(state, ends)]
        self.time, self.n_steps, self.flags = 0.0, -2, {}

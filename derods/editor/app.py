"""The editor in a browser: a viser front end wired to a :class:`~derods.editor.session.Session`.

viser serves a page (the browser renders WebGL; this process needs no GL and no display).
Every widget calls one Session method under a lock the simulation thread shares, then the
drawing is refreshed: the control points as translation gizmos, the control polygon, the
sampled rod coloured by curvature with its Bishop frames (normal red, binormal blue), a
curvature / torsion plot along the arc length; while simulating, the rod as tubes
coloured by bending strain with its material frames, pulled by dragging it with the
mouse. Loopback only unless ``host`` says otherwise; viser's public share button hidden.
"""

from __future__ import annotations

import pathlib
import threading
import time

import numpy as np
import trimesh

from ..viz.overlay import bending_strain, strain_colours

from .scene import draw_static_geoms
from .session import ENDS, RESTS, Session

#: The grab and control-point spheres' mesh: a unit icosahedron.
_ICOSPHERE = trimesh.creation.icosphere(subdivisions=0)
#: The simulation's frame period [s] (the drawing follows at this rate), and how many
#: frames of simulated time it catches up at most when it falls behind the wall clock.
FRAME = 1.0 / 30.0
MAX_BEHIND = 3


def colours(values: np.ndarray, top: float) -> np.ndarray:
    """uint8 RGB (n, 3) on the strain scale of the videos' overlays
    (:func:`derods.viz.overlay.strain_colours`: blue at 0, yellow, red at ``top``)."""
    return (255 * strain_colours(values, top)[:, :3]).astype(np.uint8)


def _hex(value: float, top: float) -> str:
    r, g, b = colours(np.array([value]), top)[0]
    return f"#{r:02x}{g:02x}{b:02x}"


def _segments(x: np.ndarray) -> np.ndarray:
    """(n - 1, 2, 3) line segments between consecutive points."""
    return np.stack([x[:-1], x[1:]], axis=1)


class EditorApp:
    """A running editor: ``EditorApp(Session("floor")).url``. ``stop()`` shuts it down."""

    def __init__(self, session: Session, host: str = "127.0.0.1", port: int = 8080):
        import viser

        self.session = session
        self.lock = threading.RLock()
        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        self.host, self.port = host, self.server.get_port()
        self.server.gui.configure_theme(show_share_button=False, control_width="medium")
        centre = np.asarray(session.samples().mean(axis=0), dtype=float)
        self.server.initial_camera.position = tuple(centre + (0.0, -1.4, 0.9))
        self.server.initial_camera.look_at = tuple(centre - (0.0, 0.0, 0.15))
        self.server.initial_camera.up = (0.0, 0.0, 1.0)
        self._gizmos: list = []
        self._nodes: dict = {}
        #: Simulated over wall time since the run (re)started (shown while running).
        self.pace: float | None = None
        draw_static_geoms(self.server.scene, self.session.scene)
        self._widgets()
        self.redraw()
        self._alive = True
        self._thread = threading.Thread(target=self._loop, name="derods-edit-sim", daemon=True)
        self._thread.start()

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}"

    def stop(self) -> None:
        self._alive = False
        self._thread.join(timeout=2.0)
        self.server.stop()

    # -- the panel ------------------------------------------------------------------------
    def _widgets(self) -> None:
        gui, s = self.server.gui, self.session
        st = s.settings
        with gui.add_folder("Curve"):
            self.samples = gui.add_slider("Samples", min=4, max=200, step=1, initial_value=st.n_edges)
            self.frames_box = gui.add_checkbox("Bishop frames", initial_value=True)
            self.colour_by = gui.add_dropdown("colour by", ("curvature", "torsion"), initial_value="curvature")
            self.legend = gui.add_markdown("")
            self.joins_group = gui.add_folder("Joins")
            self.add_seg = gui.add_button("Add segment")
            self.remove_seg = gui.add_button("Remove last segment")
        with gui.add_folder("Rod"):
            self.young = gui.add_number("E [Pa]", initial_value=st.young, min=1e3, max=1e12, step=1e3)
            self.shear = gui.add_number("G [Pa] (0: from Poisson 0.5)", initial_value=st.shear or 0.0, min=0.0,
                                        max=1e12, step=1e3)
            self.radius = gui.add_number("radius [m]", initial_value=st.radius, min=1e-4, max=0.1, step=1e-4)
            self.density = gui.add_number("density [kg/m^3]", initial_value=st.density, min=1.0, max=2e4, step=10.0)
            self.rest = gui.add_dropdown("rest shape", RESTS, initial_value=st.rest)
            self.start_end = gui.add_dropdown("start", ENDS, initial_value=st.start)
            self.end_end = gui.add_dropdown("end", ENDS, initial_value=st.end)
            self.twist = gui.add_slider("end twist [rad] (two clamps)", min=-20.0, max=20.0, step=0.1,
                                        initial_value=st.end_twist)
            self.stiffness = gui.add_markdown("")
        with gui.add_folder("Simulation"):
            self.start_btn = gui.add_button("Start")
            self.pause_btn = gui.add_button("Pause")
            self.step_btn = gui.add_button("Step")
            self.reset_btn = gui.add_button("Reset")
            self.status = gui.add_markdown("editing")
        with gui.add_folder("Michell's ring"):
            self.michell_box = gui.add_checkbox("twisted ring", initial_value=False)
            self.michell_ratio = gui.add_slider("twist / critical", min=0.0, max=2.0, step=0.01, initial_value=1.2)
            self.michell_text = gui.add_markdown("")
        with gui.add_folder("File"):
            self.path = gui.add_text("path", initial_value="rod.json")
            self.save_btn = gui.add_button("Save")
            self.load_btn = gui.add_button("Load")
            self.export_btn = gui.add_button("Export MP4 (5 s)")
            self.file_status = gui.add_markdown("")
        self.plot = gui.add_uplot(
            data=(np.zeros(2), np.zeros(2), np.zeros(2)),
            series=({"label": "s [m]"}, {"label": "curvature [1/m]", "stroke": "red"},
                    {"label": "torsion [1/m]", "stroke": "blue"}),
            title="curvature and torsion along the rod", aspect=1.6)
        self._join_widgets: list = []
        self._wire()

    def _act(self, fn):
        """A callback that runs ``fn`` under the lock, shows its error, and redraws."""
        def callback(_event=None):
            with self.lock:
                try:
                    self.file_status.content = ""
                    fn()
                except (ValueError, RuntimeError, IndexError, OSError) as err:
                    self.file_status.content = f"**{err}**"
                self.redraw()
        return callback

    def _wire(self) -> None:
        s = self.session
        self.samples.on_update(self._act(lambda: s.set_settings(n_edges=int(self.samples.value))))
        self.frames_box.on_update(self._act(lambda: None))
        self.colour_by.on_update(self._act(lambda: None))
        self.add_seg.on_click(self._act(s.add_segment))
        self.remove_seg.on_click(self._act(lambda: s.remove_segment(s.curve.n_segments - 1)))
        for handle, key, conv in ((self.young, "young", float), (self.radius, "radius", float),
                                  (self.density, "density", float), (self.rest, "rest", str),
                                  (self.start_end, "start", str), (self.end_end, "end", str),
                                  (self.twist, "end_twist", float)):
            handle.on_update(self._act(lambda h=handle, k=key, c=conv: s.set_settings(**{k: c(h.value)})))
        self.shear.on_update(self._act(lambda: s.set_settings(shear=float(self.shear.value) or None)))
        self.start_btn.on_click(self._act(s.start))
        self.pause_btn.on_click(self._act(s.pause))
        self.step_btn.on_click(self._act(lambda: s.step(1)))
        self.reset_btn.on_click(self._act(s.reset))
        self.michell_box.on_update(self._act(
            lambda: s.michell_preset(self.michell_ratio.value) if self.michell_box.value else s.edit_curve()))
        self.michell_ratio.on_update(self._act(
            lambda: s.michell_preset(self.michell_ratio.value) if self.michell_box.value else None))
        self.save_btn.on_click(self._act(lambda: s.save(self.path.value)))
        self.load_btn.on_click(self._act(lambda: s.load(self.path.value)))
        self.export_btn.on_click(self._act(self._export))

    def _export(self) -> None:
        out = pathlib.Path(self.path.value).with_suffix(".mp4")
        info = self.session.export(out, width=640, height=360)
        self.file_status.content = f"wrote {out} ({info['frames']} frames)"

    # -- drawing ----------------------------------------------------------------------------
    def redraw(self) -> None:
        """Draw what the session shows now (call under the lock)."""
        s, scene = self.session, self.server.scene
        editing = s.world is None
        self._update_gizmos(editing and s.michell is None)
        self._update_joins()
        mat = s.settings.material
        self.stiffness.content = (f"bending alpha = {mat.alpha:.3g} N m^2, twisting beta = {mat.beta:.3g} N m^2")
        self.michell_text.content = (f"critical twist 2 pi sqrt(3) alpha / beta = {s.critical_twist:.3f} rad; "
                                     f"now {self.michell_ratio.value * s.critical_twist:.3f} rad"
                                     if s.michell is not None else "")
        x = s.positions()
        if editing:
            self.status.content = "editing" + (" Michell's ring" if s.michell is not None else "")
            if s.michell is None:
                p = s.curve.points
                self._put(scene.add_line_segments("/curve/polygon", _segments(p), (150, 150, 150), thickness=0.002))
                arc, kappa, tau = s.curvature_torsion()
                field = kappa if self.colour_by.value == "curvature" else np.abs(tau)
                top = max(float(field.max()), 1e-9)
                c = colours(0.5 * (field[:-1] + field[1:]), top)
                self.legend.content = (f"<span style='color:{_hex(0, top)}'>&#9632;</span> 0 &nbsp; "
                                       f"<span style='color:{_hex(top / 2, top)}'>&#9632;</span> {top / 2:.3g} &nbsp; "
                                       f"<span style='color:{_hex(top, top)}'>&#9632;</span> {top:.3g} 1/m "
                                       f"({'|torsion|' if self.colour_by.value == 'torsion' else 'curvature'})")
                self._put(scene.add_line_segments("/curve/rod", _segments(x), np.repeat(c[:, None], 2, axis=1),
                                                  thickness=2 * s.settings.radius))
                self.plot.data = (arc, kappa, tau)
            else:
                self._remove("/curve/polygon")
                self._put(scene.add_line_segments("/curve/rod", _segments(np.vstack([x, x[:1]])), (200, 120, 40),
                                                  thickness=2 * s.settings.radius))
            self._draw_frames(x, *s.bishop_frames()[1:], "/curve/frames")
            self._remove("/sim")
        else:
            self._remove("/curve")
            self._draw_rod(x)
            pace = f"{self.pace:.2f}x real time, " if s.running and self.pace is not None else ""
            self.status.content = (f"{'running' if s.running else 'paused'}: t = {s.sim_time:.2f} s, {pace}"
                                   f"compute {s.real_time_factor:.1f}x real time")

    def _draw_frames(self, x: np.ndarray, u: np.ndarray, v: np.ndarray, name: str) -> None:
        if not self.frames_box.value:
            self._remove(name)
            return
        closed = len(u) == len(x)
        mid = 0.5 * (x + np.roll(x, -1, axis=0))[: len(u)] if closed else 0.5 * (x[:-1] + x[1:])
        size = 0.6 * float(np.mean(np.linalg.norm(np.diff(x, axis=0), axis=1)))
        seg = np.concatenate([np.stack([mid, mid + size * u], axis=1), np.stack([mid, mid + size * v], axis=1)])
        col = np.concatenate([np.tile([220, 40, 40], (len(u), 2, 1)), np.tile([40, 80, 220], (len(v), 2, 1))])
        self._put(self.server.scene.add_line_segments(name, seg, col.astype(np.uint8), thickness=0.002))

    def _draw_rod(self, x: np.ndarray) -> None:
        s = self.session
        closed = s.michell is not None
        pts = np.vstack([x, x[:1]]) if closed else x
        c = colours(s.settings.radius * bending_strain(x, closed), 0.05)  # r kappa, red at 5 %
        self._put(self.server.scene.add_line_segments("/sim/rod", _segments(pts), np.repeat(c[:, None], 2, axis=1),
                                                      thickness=2 * s.settings.radius))
        # grab points: one small sphere per vertex, dragged to pull it
        if not hasattr(self, "_grab") or self._grab_n != len(x):
            self._grab_n = len(x)
            self._grab = self._put(self.server.scene.add_batched_meshes_simple(
                "/sim/grab", _ICOSPHERE.vertices * max(2.5 * s.settings.radius, 0.01), _ICOSPHERE.faces,
                np.tile([1.0, 0, 0, 0], (len(x), 1)), x,
                batched_colors=(250, 250, 250), batched_opacities=np.full(len(x), 0.08)))
            self._grab.on_drag(self._on_pull)
        else:
            self._grab.batched_positions = x
        if s.world is not None:
            st = s.world.rod_state("rod")
            from .. import frames as fr

            m1, m2 = fr.material_frames(st.u, st.t, st.theta)
            self._draw_frames(x, m1, m2, "/sim/frames")

    def _on_pull(self, event) -> None:
        with self.lock:
            s = self.session
            if s.world is None or event.instance_index is None:
                return
            if event.phase == "end":
                s.release()
                return
            k = int(event.instance_index)
            s.pull(k, np.asarray(event.end_position, dtype=float))

    def _update_points(self, show: bool) -> None:
        """The control points as spheres that a left-drag moves (on a camera-facing plane),
        beside their gizmos (which move them along an axis or a plane)."""
        p = self.session.curve.points
        if not show:
            self._remove("/points/spheres")
            return
        colours_ = np.array([(30, 30, 30) if i % 3 == 0 else (120, 120, 120) for i in range(len(p))], dtype=np.uint8)
        handle = self._nodes.get("/points/spheres")
        if handle is not None and len(handle.batched_positions) == len(p):
            handle.batched_positions = p
            return
        handle = self._put(self.server.scene.add_batched_meshes_simple(
            "/points/spheres", _ICOSPHERE.vertices * 0.012, _ICOSPHERE.faces, np.tile([1.0, 0, 0, 0], (len(p), 1)),
            p,
            batched_colors=colours_))
        handle.on_drag(self._on_point_drag)

    def _on_point_drag(self, event) -> None:
        with self.lock:
            if self.session.world is not None or event.instance_index is None or event.phase == "start":
                return
            try:
                self.session.move_point(int(event.instance_index), np.asarray(event.end_position, dtype=float))
            except ValueError as err:
                self.file_status.content = f"**{err}**"
            self.redraw()

    def _update_gizmos(self, show: bool) -> None:
        p = self.session.curve.points if show else np.zeros((0, 3))
        while len(self._gizmos) > len(p):
            self._gizmos.pop().remove()
        for i, q in enumerate(p):
            if i < len(self._gizmos):
                self._gizmos[i].position = q
                continue
            g = self.server.scene.add_transform_controls(f"/points/p{i}", scale=0.08, disable_rotations=True,
                                                         position=q)
            g.on_update(self._gizmo_moved(i, g))
            self._gizmos.append(g)
        self._update_points(show)

    def _gizmo_moved(self, i: int, handle):
        def callback(_event):
            with self.lock:
                if self.session.world is not None:
                    return
                try:
                    self.session.move_point(i, np.asarray(handle.position, dtype=float))
                except ValueError as err:
                    self.file_status.content = f"**{err}**"
                self.redraw()
        return callback

    def _update_joins(self) -> None:
        joins = self.session.curve.joins
        if [w.value for w in self._join_widgets] == list(joins):
            return
        for w in self._join_widgets:
            w.remove()
        self._join_widgets = []
        with self.joins_group:
            for j, c in enumerate(joins, start=1):
                w = self.server.gui.add_dropdown(f"join {j}", ("C0", "C1"), initial_value=c)
                w.on_update(self._act(lambda j=j, w=w: self.session.set_join(j, w.value)))
                self._join_widgets.append(w)

    def _put(self, handle):
        """Keep a drawn node's handle by its name (re-adding a name replaces the node)."""
        self._nodes[handle.name] = handle
        return handle

    def _remove(self, prefix: str) -> None:
        for name in [n for n in self._nodes if n.startswith(prefix)]:
            self._nodes.pop(name).remove()
        if prefix == "/sim" and hasattr(self, "_grab"):
            del self._grab

    # -- the simulation thread --------------------------------------------------------------
    def _loop(self) -> None:
        """Keep the simulated time on the wall clock while running (at most MAX_BEHIND
        frames of catching up at once), drawing once per frame."""
        paced = None  # (wall, sim) when the run (re)started
        while self._alive:
            t0 = time.perf_counter()
            with self.lock:
                s = self.session
                if s.running and s.world is not None:
                    if paced is None:
                        paced = (t0, s.sim_time)
                    if t0 - paced[0] > 0.5:
                        self.pace = (s.sim_time - paced[1]) / (t0 - paced[0])
                    behind = (t0 - paced[0]) - (s.sim_time - paced[1])
                    if behind > MAX_BEHIND * FRAME:  # too slow for real time: stop trying to catch up
                        paced = (t0 - MAX_BEHIND * FRAME, s.sim_time)
                        behind = MAX_BEHIND * FRAME
                    try:
                        s.advance(max(behind, 0.0))
                    except Exception as err:  # a diverged rod: stop, say why
                        s.pause()
                        self.file_status.content = f"**{err}**"
                    self.redraw()
                else:
                    paced, self.pace = None, None
            time.sleep(max(0.0, FRAME - (time.perf_counter() - t0)))


def serve(scene: str = "floor", host: str = "127.0.0.1", port: int = 8080) -> None:
    """``derods edit``: run the editor until Ctrl-C."""
    app = EditorApp(Session(scene), host=host, port=port)
    try:  # before the URL is printed: a Ctrl-C right after it is still a clean stop
        print(f"derods edit: open {app.url} in a browser (Ctrl-C to stop)", flush=True)
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        print("derods edit: stopped (save the rod with the page's Save button before stopping)", flush=True)
    finally:
        app.stop()

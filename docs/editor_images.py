"""Regenerate the README's screenshots of the browser editor: ``make docs-editor``.

Serves the editor (derods.editor.app) on the box scene, opens it in headless Debian
chromium through playwright, sets each state through the Session (as the widgets do)
and saves what the browser shows:

docs/editor_c1.png: edit mode, the default wave, both joins C1 (handles mirrored);
docs/editor_c0.png: edit mode with a C0 corner at the join (a handle dragged off line);
docs/editor_running.png: the rod simulated on the box, coloured by bending strain;
docs/editor_michell.png: Michell's ring twisted to 1.3 times the critical twist, buckled.
"""

from __future__ import annotations

import pathlib
import shutil
import time

DOCS = pathlib.Path(__file__).resolve().parent
ARGS = ["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--disable-background-networking",
        "--disable-component-update", "--disable-sync", "--no-first-run"]


def main() -> None:
    from playwright.sync_api import sync_playwright

    from derods.editor.app import EditorApp
    from derods.editor.session import Session, Settings

    chromium = shutil.which("chromium")
    if chromium is None:
        raise SystemExit("docs/editor_images.py needs Debian's chromium: apt-get install chromium")
    app = EditorApp(Session("box", settings=Settings(n_edges=40, dt=5e-3)), port=0)
    s = app.session
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium, args=ARGS, headless=True)
        page = browser.new_page(viewport={"width": 1280, "height": 720})
        page.set_default_timeout(90_000)
        page.goto(app.url)
        page.get_by_text("Connected").wait_for()
        page.get_by_role("button").first.wait_for()

        def shot(name: str, settle: float = 2.0) -> None:
            time.sleep(settle)
            page.screenshot(path=str(DOCS / name))
            print(f"wrote docs/{name}")

        shot("editor_c1.png")
        app._join_widgets[0].value = "C0"  # the join's dropdown, as a user picks it
        with app.lock:
            s.move_point(4, [0.05, -0.25, 0.62])  # what a drag on handle 4 does
            app.redraw()
        shot("editor_c0.png")
        app._join_widgets[0].value = "C1"
        page.get_by_role("button", name="Start").click()
        while s.sim_time < 2.0:
            time.sleep(0.05)
        page.get_by_role("button", name="Pause").click()
        shot("editor_running.png")
        page.get_by_role("button", name="Reset").click()
        for widget, value in ((app.young, 1e7), (app.shear, 5e6), (app.radius, 0.005), (app.michell_ratio, 1.3)):
            widget.value = value
        app.michell_box.value = True
        with app.lock:
            s.set_settings(dt=1e-2)
        page.get_by_role("button", name="Start").click()
        # The ring leaves its plane within ~1 s (out of plane by 0.44 R at 2 s); with no
        # self-contact it later passes through itself and unwinds.
        while s.sim_time < 1.6:
            time.sleep(0.05)
        page.get_by_role("button", name="Pause").click()
        shot("editor_michell.png")
        browser.close()
    app.stop()


if __name__ == "__main__":
    main()

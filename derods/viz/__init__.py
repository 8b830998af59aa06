"""Pictures and videos: off-screen GL rendering (:mod:`derods.viz.render`), the files
derods writes, atomically (:mod:`derods.viz.output`), a world filmed to a video
(:mod:`derods.viz.filming`), overlays drawn into MuJoCo scenes (:mod:`derods.viz.overlay`)
and the figures of the paper's cases (:mod:`derods.viz.figures`)."""

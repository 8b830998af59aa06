"""Pictures and videos: off-screen rendering (:mod:`derods.viz.render`), overlays drawn
into MuJoCo scenes (:mod:`derods.viz.overlay`) and the figures of the paper's cases
(:mod:`derods.viz.figures`)."""

"""Reading rods declared in MJCF files.

:mod:`derods.io.mjcf_load` turns a MuJoCo model file into a scene and the derods rods
it declares: MuJoCo 3.x cable composites (``<composite type="cable">``, whose
``B_first`` / ``B_last`` bodies and ``S_first`` / ``S_last`` sites stay in the scene,
holding the rod's end edges) and, on request, MuJoCo's 1D flexcomps.
:mod:`derods.io.cable_geometry` is the geometry MuJoCo's composite builds (its
vertices and body frames) and the sections it reads; :mod:`derods.io.mjcf_cable` and
:mod:`derods.io.mjcf_flexcomp` read one element each. ``World(path)`` calls them.
"""

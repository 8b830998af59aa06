"""The rod editor's logic: the curve a user shapes (:mod:`~derods.editor.curve`) and the
editing session that makes a rod of it and simulates it (:mod:`~derods.editor.session`).
No user interface lives here: a front end wires its widgets to
:class:`~derods.editor.session.Session`'s methods."""

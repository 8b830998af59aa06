"""Rods in MuJoCo: the :class:`World` facade and the concerns behind it."""

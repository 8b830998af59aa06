"""What users run: the drop-and-film job (:mod:`derods.apps.drop`) and the command line
(:mod:`derods.apps.cli`)."""

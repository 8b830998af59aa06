"""What users run: the drop-and-film job (:mod:`derods.apps.drop`), the hair video
(:mod:`derods.apps.hair`), the command line's options and exit codes (:mod:`derods.apps.cli`)
and what each subcommand does (:mod:`derods.apps.commands`)."""

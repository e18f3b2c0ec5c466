"""The recipe schema: every job's keys declared once, and what derives from them.

- :mod:`.key`: one key's declaration (:class:`~porecad.recipes.key.Key`: kind, default, bounds, help, ...);
- :mod:`.keys`: every job's keys (:data:`~porecad.recipes.keys.JOBS`);
- :mod:`.table`: checked reads of one recipe table (:class:`~porecad.recipes.table.Table`);
- :mod:`.schema`: the JSON Schema, the generated docs and the defaults other layers show.

Pure Python (no numpy): the command line's help and the studio read it without loading the jobs.
"""

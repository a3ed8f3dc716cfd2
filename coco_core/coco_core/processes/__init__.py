"""The process level of the scheduling tree: activities in child processes of the launcher.

``<process>`` elements in the application file put activities into child processes; everything else
stays in the launcher's process, exactly as without them. :func:`process_level` is what both
launchers wrap around a run: it starts the children (each builds only its own components), ties
their life to the application's, and gives the one profile report of every process.
"""

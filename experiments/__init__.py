"""experiments: scripted reproductions, studies, figures and the ``skysim`` command line."""

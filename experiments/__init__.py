"""experiments: the ``skysim`` command line (:mod:`.cli`), the services behind its commands
(:mod:`.workflows`), the reproductions and studies (:mod:`.studies`) and their figures
(:mod:`.plotting`)."""

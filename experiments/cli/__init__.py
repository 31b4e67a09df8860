"""The ``skysim`` command line: dispatch and error handling (:mod:`.main`), option types
(:mod:`.argtypes`), the static index of commands (:mod:`.command_index`), the shared
``--clouds`` options (:mod:`.cloud_options`) and the foundation commands ``sky``, ``sample``
and ``calibrate`` (:mod:`.commands`)."""

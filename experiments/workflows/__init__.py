"""Services behind the ``skysim`` commands: error-sensitivity sweeps (:mod:`.sweep`, its
configuration :mod:`.sweep_config` and execution backends :mod:`.sweep_backends`), ground-truth
data sets (:mod:`.generate`), sky-map time series (:mod:`.sky_series`), the gap diagnosis of a
data file and its blind benchmark (:mod:`.diagnose`, with the effect injector for real sessions
:mod:`.real_injection`), and what every long command shares: output folders replaced as a
whole (:mod:`.run_folder`) and progress, duration announcements and warnings
(:mod:`.progress`)."""

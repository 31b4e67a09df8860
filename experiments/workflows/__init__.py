"""Services behind the ``skysim`` commands: error-sensitivity sweeps (:mod:`.sweep`, its
configuration :mod:`.sweep_config` and execution backends :mod:`.sweep_backends`), ground-truth
data sets (:mod:`.generate`), sky-map time series (:mod:`.sky_series`), the gap diagnosis of a
data file and its blind benchmark (:mod:`.diagnose`, on real sessions :mod:`.real_benchmark`
with the effect injector :mod:`.real_injection`), and what the commands of every layer share:
option types and input/output checks (:mod:`.options`), the sky-model options and view
directions (:mod:`.sky_options`), the ``--clouds`` options (:mod:`.cloud_options`), output
folders replaced as a whole (:mod:`.run_folder`) and progress, duration estimates and
warnings (:mod:`.progress`)."""

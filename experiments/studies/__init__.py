"""Reproductions of published experiments and studies of skysim's own, one module each, each a
``skysim reproduce`` target (and some a command of their own): Yang et al. (2014)
(:mod:`.yang2014`), Jin et al. (2020) (:mod:`.jin2020`), the compound-eye installation
calibration (:mod:`.compound_eye`), dark current in weak light (:mod:`.dark_current`), the
physically based sky (:mod:`.physical_sky`, with its aerosol part :mod:`.aerosol_sky`), the
sky-level gap on the Natraj tables (:mod:`.sky_gap`), real ring-compass sessions
(:mod:`.real_compass`), the moonlit sky and compass (:mod:`.moonlit_sky`,
:mod:`.moonlit_compass`), the cloudy compass (:mod:`.cloudy_compass`) and the polarization
camera (:mod:`.camera`)."""

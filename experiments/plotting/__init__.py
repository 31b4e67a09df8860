"""Figures: the headless pyplot and atomic PNG writes every figure uses (:mod:`.figures`),
polar (fish-eye) sky maps (:mod:`.polar_maps`) and the Yang et al. (2014) figures
(:mod:`.yang2014_figures`)."""

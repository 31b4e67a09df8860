"""Division-of-focal-plane polarization camera: fisheye lens, micro-polarizer mosaic sensor,
demosaicing to Stokes images and raw image files."""

from .demosaic import (DEMOSAIC_METHODS, StokesImage, camera_stokes, demosaic,
                       local_meridian_aop)
from .lens import LENS_MODELS, FisheyeLens
from .mosaic import (DEFAULT_LAYOUT_DEG, SUN_RADIUS_DEG, MosaicSensor, PolarizationCamera,
                     Scene, camera_attitude, camera_basis)

__all__ = ["DEFAULT_LAYOUT_DEG", "DEMOSAIC_METHODS", "LENS_MODELS", "SUN_RADIUS_DEG",
           "FisheyeLens", "MosaicSensor", "PolarizationCamera", "Scene", "StokesImage",
           "camera_attitude", "camera_basis", "camera_stokes", "demosaic", "local_meridian_aop"]

"""Identification: circle point analysis, geometric and effect fits, identifiability.

The defaults every caller shares (the CLI, the flows, the calibrator node) live here, in
the package's light `__init__` (importing it loads no solver).
"""

DEFAULT_MODEL = "geometric"  # the model `calibrate` identifies unless told otherwise
DEFAULT_ECC_ORDER = 1  # the seed's Fourier order of eccentricity (90 terms on 6 joints)

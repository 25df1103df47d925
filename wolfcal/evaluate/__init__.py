"""`wolfcal evaluate`: held-out error of a fit before/after, in pixels, millimetres and metres on the field.

metrics (corner and tag-grid errors), ground (where a ball lands), crossval (k-fold without a held-out capture),
figures (PNG pictures), report (HTML / Markdown / terminal table), deploy (URDFs, offsets, camera correction),
pipeline (`run_evaluate`, the whole job).
"""

"""`wolfcal evaluate`: held-out error of a fit before/after, in pixels, millimetres and metres on the field.

metrics (corner and tag-grid errors), ground (where a ball lands), crossval (k-fold without a held-out capture),
report_content (the report's texts, tables and per-sample records), report_figures (which pictures, with captions),
figures (drawing them as PNG), report (rendering as HTML / Markdown / terminal table), deploy (URDFs, offsets,
camera correction), pipeline (`run_evaluate`, the whole job).
"""

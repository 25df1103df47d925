"""`wolfcal evaluate`: held-out error of a fit before/after, in pixels, millimetres and metres on the field.

metrics (corner and tag-grid errors), ground (where a ball lands), floor_ground (the ground error measured on held-out
floor views), structure (whether the model explains the residuals), external (held-out external-camera captures),
crossval (k-fold without a held-out capture), verdict (whether to deploy), report_content (the report's texts, tables
and per-sample records), report_figures (which pictures, with captions), figures (drawing them as PNG), report
(rendering as HTML / Markdown / terminal table), deploy (URDFs, offsets, camera correction), pipeline
(`run_evaluate`, the whole job); compare (`wolfcal compare`: several calibrations side by side); accuracy (a model
against a simulator's truth, for tests and benches).
"""

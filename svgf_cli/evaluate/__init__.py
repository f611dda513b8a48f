"""`svgf evaluate`: image-quality and temporal-stability metrics, baselines, reports, plots."""

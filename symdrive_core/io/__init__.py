"""File formats: splat PLY (numpy only), images via OpenImageIO, atomic writes."""

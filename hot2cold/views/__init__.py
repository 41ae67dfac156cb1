"""Looking at a morph: pictures (:mod:`.pictures`: overlays, error maps, curvature, with matplotlib) and
the self-contained HTML report (:mod:`.page`)."""

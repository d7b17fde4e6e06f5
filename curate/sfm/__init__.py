"""Photos (and videos) to cameras: ingest, quality, COLMAP (the only pycolmap user), pose imports, the sfm stage."""

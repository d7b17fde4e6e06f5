"""The export stage: the chosen subset as COLMAP, transforms.json, an image list and links."""

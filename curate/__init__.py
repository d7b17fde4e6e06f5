"""curate: pick the best photos of a capture for NeRF / Gaussian splatting.

Implements and extends Kopanas & Drettakis, "Improving NeRF Quality by Progressive
Camera Placement for Free-Viewpoint Navigation" (VMV 2023).
"""

__version__ = "0.3.0"

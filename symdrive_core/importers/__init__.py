"""Importers: recorded drives reconstructed by COLMAP, nerfstudio or the 3DGS trainer, or recorded
by KITTI's stereo rig, become scene packages in a metric, Z-up world
(``symdrive import colmap|nerfstudio|3dgs|kitti``).

One module per idea: :mod:`.colmap`, :mod:`.nerfstudio`, :mod:`.gs_trainer`, :mod:`.kitti` read
their formats into :class:`~.frames.View` records; :mod:`.frames` groups them into cameras and
frames; :mod:`.triangulate` triangulates points from the images of a drive that has none (poses
fixed); :mod:`.undistort` turns lensed cameras into pinhole ones through COLMAP's undistorter;
:mod:`.stereo` takes a rectified rig's second camera out as lateral ground truth;
:mod:`.ground` finds the ground plane and the similarity to a metric Z-up world;
:mod:`.similarity` applies it to cameras and splats (SH colours rotated); :mod:`.package` writes
the package atomically.
"""

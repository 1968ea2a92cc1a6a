"""Traffic from SUMO: the scene's road as a SUMO network, dense flow and scripted manoeuvres
(TraCI, closed loop), read back as per-frame vehicle poses for a scene package.

road -> network (netconvert) -> demand (routes) -> sumo_run -> fcd -> actors -> overlap -> package.
"""

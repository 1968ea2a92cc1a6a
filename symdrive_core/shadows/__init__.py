"""Vehicles' sun shadows on the ground: the region one may cover (:mod:`.region`), the shadow
cast by a vehicle's Gaussians (:mod:`.cast`), and a recorded vehicle's learnt shadow layer
(:mod:`.layer`). Below fitting and insertion, which both lay them."""

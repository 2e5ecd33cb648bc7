"""breastplan filters on a pymeshlab MeshSet, pymeshlab-style."""

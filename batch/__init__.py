"""Clinic scale: every scan and recording of a folder planned as `plan` does, locally or on a Dask cluster."""

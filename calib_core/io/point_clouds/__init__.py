"""One reader per point-cloud file format, each returning a :class:`~.cloud.PointCloud`.

Use :func:`calib_core.io.scan_readers.read_point_cloud`, which picks the reader
by extension and applies the checks common to every format.
"""

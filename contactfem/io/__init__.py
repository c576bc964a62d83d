"""Output writers: ParaView VTU/PVD files and the HDF5 archive, all written atomically."""

from contactfem.io.atomic import atomic_path, atomic_write_text
from contactfem.io.hdf5 import read_hdf5, write_hdf5
from contactfem.io.vtu import write_vtu

__all__ = ["atomic_path", "atomic_write_text", "read_hdf5", "write_hdf5", "write_vtu"]

"""The physics core: parameters, the 7-DOF equations, road contact, exact discretisation and the compiled kernel.

Pure functions over arrays: no files, no printing."""

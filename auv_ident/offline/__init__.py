"""The offline application on top of the bag I/O: replay of a bag through the identifier's
session, imports of measured runs (HSVA, CSV with a column map) and simulated runs as bags."""

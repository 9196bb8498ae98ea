"""Transports: thin owners of devices (pyserial ports, python-can buses)."""

"""Virtual CiA 402 servo drives on a simulated CAN bus, and the master-side axis group."""

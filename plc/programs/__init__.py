"""The standard PLC programs shipped with fmscell (ladder text, `*.ld`)."""

"""``fieldcal capture``: a live stream of lines from a device (serial port, standard input, a
followed file) recorded as it comes, still poses detected as they happen, a running
calibration and the next pose to take."""

"""From a log file to poses: readers, column recognition, still detection, streaming apply."""

"""Phase II of the paper (section V): six error motions from the IMU, backlash by signal
shifts and by perceived pitch, trend and prognosis. Works on ``measurements.h5`` alone."""

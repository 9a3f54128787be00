"""Training scans as other phones might see them, drawn afresh each epoch."""

import numpy as np


class ScanAugmenter:
    """
    Phone-like variations of a scan matrix (NaN = not detected).

    Per scan a gain and an offset, per reading Gaussian noise and random
    loss; readings pushed below the not-detected floor are lost. Only the
    detected readings are touched, so an epoch costs a few dozen readings
    per scan rather than the whole matrix.
    """

    def __init__(self, rssi, config, seed):
        self.shape = rssi.shape
        self.rows, self.cols = np.nonzero(~np.isnan(rssi))
        self.values = rssi[self.rows, self.cols].astype(np.float32)
        self.config = config
        self.floor = config.not_detected if config.not_detected < 0 \
            else -110.0
        self.rng = np.random.default_rng(seed)

    def readings(self):
        """
        Return (rows, columns, dBm) of a freshly augmented set of readings.

        Rows are in ascending order; readings pushed below the floor or
        dropped are left out.
        """
        c, rng, n = self.config, self.rng, self.shape[0]
        gain = rng.uniform(-c.augment_gain, c.augment_gain, n)
        offset = rng.uniform(-c.augment_offset, c.augment_offset, n)
        values = self.values * (1 + gain[self.rows]).astype(np.float32) \
            + offset[self.rows].astype(np.float32)
        if c.augment_noise:
            values += c.augment_noise * rng.standard_normal(
                len(values), dtype=np.float32)
        kept = (rng.random(len(values), dtype=np.float32) >=
                c.augment_dropout) & (values >= self.floor)
        return (self.rows[kept], self.cols[kept],
                np.minimum(values[kept], np.float32(0.0)))

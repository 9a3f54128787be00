"""Turn RSSI vectors (NaN = not detected) into network inputs."""

import numpy as np

SCALINGS = ('joint', 'independent')
#: dBm as is (undetected = ``not_detected``), or a positive signal in
#: [0, 1] that is 0 for undetected APs (Torres-Sospedra et al. 2015):
#: ``powed`` = ((dBm - floor) / -floor) ** e, ``exponential`` =
#: (exp((dBm - floor) / 24) - 1) / (exp(-floor / 24) - 1), with floor =
#: ``not_detected``.
REPRESENTATIONS = ('dbm', 'powed', 'exponential')
#: Non-negative signals (0 = not detected) the position k-NN can compare:
#: ``positive`` = dBm - floor, and the two above.
SIGNALS = ('positive', 'powed', 'exponential')


def signal(rssi, representation, floor=-110.0):
    """Return float32 ``rssi`` (NaN = not detected) as a non-negative signal."""
    if representation not in SIGNALS:
        raise ValueError(f'signal representation must be one of {SIGNALS}, '
                         f'not {representation!r}')
    floor = np.float32(floor)
    above = np.fmax(np.asarray(rssi, np.float32) - floor, np.float32(0.0))
    if representation == 'positive':
        return above
    if representation == 'powed':
        return (above / -floor) ** np.float32(np.e)
    return (np.expm1(above / 24) / np.expm1(-floor / 24)).astype(np.float32)


def signal_dbm(value, representation, floor=-110.0):
    """Return the dBm (float64) of :func:`signal` values: its inverse."""
    value = np.asarray(value, np.float64)
    if representation == 'positive':
        return floor + value
    if representation == 'powed':
        return floor - floor * value ** (1 / np.e)
    return floor + 24 * np.log1p(value * np.expm1(-floor / 24))


class NotFittedError(ValueError, AttributeError):
    """A scaler used before :meth:`RssiScaler.fit`."""


class RssiScaler:
    """
    Fill not-detected APs with a constant, then standardise.

    ``scaling='joint'`` uses one mean/std over every RSSI value (the paper's
    best); ``'independent'`` one mean/std per AP. ``not_detected`` is the dBm
    value given to undetected APs (paper: -110; 100 reproduces the raw file).
    """

    def __init__(self, not_detected=-110.0, scaling='joint',
                 representation='dbm'):
        if scaling not in SCALINGS:
            raise ValueError(f'scaling must be one of {SCALINGS}, '
                             f'not {scaling!r}')
        if representation not in REPRESENTATIONS:
            raise ValueError(f'representation must be one of '
                             f'{REPRESENTATIONS}, not {representation!r}')
        if representation != 'dbm' and not not_detected < 0:
            raise ValueError(f'{representation} needs a negative '
                             f'not_detected floor')
        self.not_detected = float(not_detected)
        self.scaling = scaling
        self.representation = representation

    def fill(self, rssi):
        """Return the representation, with undetected APs filled in."""
        rssi = np.asarray(rssi, dtype=np.float32)
        if self.representation == 'dbm':
            return np.where(np.isnan(rssi), np.float32(self.not_detected),
                            rssi)
        return signal(rssi, self.representation, self.not_detected)

    def fit(self, rssi):
        """Learn mean and std from training scans."""
        x = self.fill(rssi).astype(np.float64)
        if self.scaling == 'joint':
            mean = np.full(x.shape[1], x.mean())
            std = np.full(x.shape[1], x.std())
        else:
            mean, std = x.mean(axis=0), x.std(axis=0)
        self.mean_ = mean.astype(np.float32)
        self.std_ = np.where(std > 1e-6, std, 1.0).astype(np.float32)
        return self

    def transform(self, rssi, columns=None):
        """
        Return standardised float32 inputs, shape (n, n_aps).

        With ``columns``, ``rssi`` holds only those APs' values (last axis).
        """
        if not hasattr(self, 'mean_'):
            raise NotFittedError('this RssiScaler is not fitted yet: call '
                                 'fit() with training scans first')
        if columns is None:
            rssi = np.asarray(rssi)
            if rssi.shape[-1:] != self.mean_.shape:
                raise ValueError(f'expected {len(self.mean_)} AP columns '
                                 f'(fitted width), got shape {rssi.shape}')
            return (self.fill(rssi) - self.mean_) / self.std_
        return (self.fill(rssi) - self.mean_[columns]) / self.std_[columns]

    def blank(self):
        """Return the inputs (n_aps,) of a scan that detects nothing."""
        return self.transform(np.full((1, len(self.mean_)), np.nan,
                                      np.float32))[0]

    def params(self):
        """Return the JSON-able parameters (arrays go separately)."""
        return {'not_detected': self.not_detected, 'scaling': self.scaling,
                'representation': self.representation}

    def arrays(self):
        """Return the fitted arrays, keyed by name."""
        return {'scaler.mean': self.mean_, 'scaler.std': self.std_}

    @classmethod
    def restore(cls, params, arrays):
        """Rebuild a fitted scaler from :meth:`params` and :meth:`arrays`."""
        scaler = cls(params['not_detected'], params['scaling'],
                     params.get('representation', 'dbm'))
        scaler.mean_ = arrays['scaler.mean']
        scaler.std_ = arrays['scaler.std']
        return scaler

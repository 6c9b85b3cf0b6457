"""accal: calibration of spacecraft electrostatic-accelerometer data.

Two jobs share one data model (:class:`accal.series.AccSeries`) and one
reader -> estimator -> writer pipeline:

* ``accal grace-bias``: per-day, per-axis bias and drift of GRACE / GRACE-FO
  Level-1B accelerometer data (wavelet detrending and least squares).
* ``accal demod``: unbiased acceleration from a rotating-platform
  accelerometer (MicroSTAR + Bias Rejection System).
"""

__version__ = "0.1.0"

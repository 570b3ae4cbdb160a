"""The photodiode chain: irradiance -> photocurrent -> noise -> transimpedance -> ADC counts
(thesis eqs. 2.26-2.28, 4.16-4.25), with the shipped diode types."""

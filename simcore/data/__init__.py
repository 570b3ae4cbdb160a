"""The shipped data files (what each is and where it comes from: README.md), read through
``importlib.resources``; code here (``band/build_band_data.py``, run offline by hand) imports nothing of sunsim."""

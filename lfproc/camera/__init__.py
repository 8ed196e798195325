"""The paper's coded multi-ISO camera (stage 4 of the pipeline, and the model stage 5 inverts).

* :mod:`~lfproc.camera.sensor`: the sensor's noise model (exposure, calibrated observations);
* :mod:`~lfproc.camera.projection`: mask codes, the Bayer CFA and the projection operator ``Phi``;
* :mod:`~lfproc.camera.iso`: per-pixel ISO layouts;
* :mod:`~lfproc.camera.capture`: capture files (simulated or imported from raw files);
* :mod:`~lfproc.camera.simulate`: simulated captures of HDR light fields.

Imports go one way: ``sensor``, ``projection``, ``iso`` <- ``capture`` <- ``simulate``.
"""

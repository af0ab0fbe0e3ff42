"""The application layer: every use case of the command line as a plain, typed function.

The command line (:mod:`thermodepth.cli`) only parses options, calls one of these and prints
what it returns; scripts and tests call them the same way. Bad input raises
:class:`~thermodepth.errors.InputError` (a :class:`~thermodepth.errors.FieldError` names the
argument, which the command line shows as its option). Long work reports through a
:class:`~thermodepth.progress.Reporter`.

=====================  ======================================================================
module                 use cases
=====================  ======================================================================
:mod:`.run`            ``run`` (fuse a stream into measurements, with the sinks it asks for)
:mod:`.record`         ``record`` (a source into a crash-safe recording)
:mod:`.batch`          ``batch`` (many recordings measured again on a dask cluster; its
                       summary in :mod:`.batch_summary`)
:mod:`.calibrate`      ``calibrate``, ``calibrate_camera``, ``check_calibration``
:mod:`.capture`        ``capture_board`` (the pairs of a stream worth calibrating with)
:mod:`.collect`        ``collect_sweep`` (sweep rows from a session in front of a plate)
:mod:`.compensation`   ``fit_compensation``, ``compensate_file``, ``evaluate``, ``paper_tables``
:mod:`.simulate`       ``sweep``, ``frames``, ``targets``, ``board_session``, ``protocol`` on
                       the simulated rig
:mod:`.temperature`    ``counts_to_celsius``
:mod:`.emissivity`     ``measure_emissivity`` (a target ROI's emissivity against a reference
                       ROI), ``write_roi_emissivity`` (into the settings YAML)
:mod:`.devices`        ``list_devices``, ``describe_devices``
:mod:`.demo`           ``run_demo``: the whole story on the simulated rig
:mod:`.monitor`        ``run_monitor`` (the always-on monitor of a config, until stopped),
                       ``describe_config`` (``monitor --check``)
:mod:`.report`         ``make_report`` (the inspection report of a period from a monitor's
                       event store and readings; drawn by :mod:`.report_render`)
=====================  ======================================================================
"""

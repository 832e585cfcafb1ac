"""Research harnesses: they import the package (``servo``, ``kernels``), never the reverse,
and are not installed with it; run them from a checkout (``python -m studies.NAME``).

* :mod:`studies.proving`: the independent proving ground of ``servo diagnose``;
* :mod:`studies.concealed`: the concealed-effect study on the simulated drive;
* :mod:`studies.memprobe`: the peak memory of a diagnosis;
* :mod:`studies.hdd`: the HDD benchmark's evaluation of a design over its 54 plants;
* :mod:`studies.identity`: bit-identity of a change that must not change behaviour.
"""

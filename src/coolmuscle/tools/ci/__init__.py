"""What the commands write for a CI system to read: JUnit XML (:mod:`.junit`), GitHub
workflow commands (:mod:`.github`) and Cobertura coverage XML (:mod:`.cobertura`).

Plain writers of the formats, named after what a CI reads; each command decides what
its test cases, annotations or covered lines are (``batch``, ``run --check``,
``compare``, ``check``; the test plug-in's bank coverage).  Standard library only.
"""

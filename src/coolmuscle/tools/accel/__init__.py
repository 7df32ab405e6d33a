"""The compiled hot modules (docs/performance.md): ``python -m coolmuscle.tools.accel
build|status|clean`` (:mod:`.build`)."""

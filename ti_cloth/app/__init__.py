"""The application on top of the library and the renderer: scene files (scene.py, read strictly
by inputs/scene_file.py), running them into frames (runner.py), the speed/accuracy study
(study.py, reported by study_report.py) and the `ti-cloth` command (cli.py). Nothing outside
this package imports it (tests/test_layers.py)."""
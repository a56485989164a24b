"""The 3D view (Rviz2 replacement): ``scene.Viewer`` turns bus snapshots into a viser scene and
``relay.make_router`` serves it through the dashboard's port at ``/viz/``. Import the submodules
directly; this package stays import-light so ``navdeck --help`` does not load viser."""

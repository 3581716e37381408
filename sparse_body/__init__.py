"""sparse_body: whole-body pose from sparse trackers.

The ROS-free core lives in core/, data/, estimators/ and methods/; transports without ROS in
adapters/, files in io/, the nodes in ros/, training in train/, and what the command runs in
apps/ (cli.py is the entry point).
"""

from pkgutil import extend_path

# The interfaces generated from msg/ (sparse_body.msg) are installed by CMake into the
# environment's site-packages, outside this directory; merge that portion into the package.
__path__ = extend_path(__path__, __name__)

__version__ = "0.1.0"

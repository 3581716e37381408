"""sparse_body: whole-body pose from sparse trackers.

The ROS-free core lives in core/, data/ and estimators/; ROS nodes live in ros/.
"""

from pkgutil import extend_path

# The interfaces generated from msg/ (sparse_body.msg) are installed by CMake into the
# environment's site-packages, outside this directory; merge that portion into the package.
__path__ = extend_path(__path__, __name__)

__version__ = "0.1.0"

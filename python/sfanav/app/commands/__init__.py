"""The ``sfanav`` subcommands, one module per family. Importing this
package registers them (in this order, the order of ``sfanav --help``)
with :func:`sfanav.app.registry.command`."""
# isort: skip_file
# the import order is the order of the subcommands in the help

from . import simulate  # noqa: F401
from . import bag_import  # noqa: F401
from . import train  # noqa: F401
from . import update  # noqa: F401
from . import localize  # noqa: F401
from . import ros_node  # noqa: F401
from . import navigate  # noqa: F401
from . import groundtruth  # noqa: F401
from . import features  # noqa: F401
from . import experiment  # noqa: F401

"""The UAV sensor-release case study, a package of its own over the generic simulator.

UAVs fly to hot zones and release wireless sensors that fall and land; the case study scores the network they
form. Its parts:

* ``scenario`` (the ``uav_release`` scenario), ``config``, ``zones`` (zone files), ``energy``, ``autopilot``,
  ``tracking``, ``outcome``, ``capacity`` and ``landed_grid``: the scenario and what it is built from;
* ``wsn``: the wireless-sensor-network evaluator of a landed layout (coverage, connectivity, lifetime);
* ``evaluation``: the runner that flies every release strategy over zone files and seeds, and its report;
* ``designer``: the hot-zone designer page and its server; ``data``: the default zone files;
* ``cli``: the ``agentsim evaluate`` and ``agentsim zones`` subcommands.

Nothing generic imports this package: the scenario registry names ``uav_release`` by a ``"module:attr"``
string, the viewer draws what ``Scenario.markers()`` returns, and the command line adds the subcommands through
its list of subcommand providers. The release strategies (``agentsim_env.policies.release``) sit above it.
Importing the package imports none of its modules.
"""

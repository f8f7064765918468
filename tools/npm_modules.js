// Where the test-time npm packages of the tools/*.js scripts live: $LODSTREAM_NPM_PREFIX/node_modules (an
// npm --prefix), then $HOME/.cache/lodstream-npm/node_modules (tools/install-deps.sh --test,
// tools/install_tiles_tools.sh and tools/bench_grid.sh install them there).
'use strict';

const fs = require('fs');
const path = require('path');

// The directory of package `name`, or null when it is not installed.
function findModule(name) {
  const dirs = [];
  if (process.env.LODSTREAM_NPM_PREFIX) dirs.push(path.join(process.env.LODSTREAM_NPM_PREFIX, 'node_modules'));
  if (process.env.HOME) dirs.push(path.join(process.env.HOME, '.cache', 'lodstream-npm', 'node_modules'));
  for (const dir of dirs) if (fs.existsSync(path.join(dir, name, 'package.json'))) return path.join(dir, name);
  return null;
}

module.exports = { findModule };

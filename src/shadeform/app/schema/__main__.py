"""``python -m shadeform.app.schema``: print the web client's TypeScript types (``web/src/api.gen.ts``)."""

import sys

from shadeform.app.schema.generate import typescript

sys.stdout.write(typescript())

// Drives `lightbake view` in headless Chromium (playwright-core, Debian's /usr/bin/chromium):
// node tests/view_browser.js URL OUT_DIR WIDTH HEIGHT READ_SIDE [VIEW...]
// Writes OUT_DIR/lit.json (the lit view from glTF camera 0, READ_SIDE² pixels of linear RGB,
// rows from the top) and
// OUT_DIR/<view>.png (the canvas in each view). With LIGHTBAKE_PROBE_SPOTS set to a JSON list
// of {"sphere": [x,y,z], "eye": [x,y,z]}, it also moves the probe-lit sphere to each spot, looks
// at it from the eye and writes OUT_DIR/probes.json ({"spots": [{"sh": 27 floats, "centre":
// linear RGB of the centre pixel}]}), and the lit view from glTF camera 0 with the probes hidden
// and shown (probes_off.png, probes_on.png). Exits non-zero on any page error.
const fs = require('fs');
const os = require('os');
const path = require('path');
const { chromium } = require('playwright-core');

async function main() {
  const [url, out, width, height, readSide, ...views] = process.argv.slice(2);
  const size = { width: +width, height: +height };
  const profile = fs.mkdtempSync(path.join(os.tmpdir(), 'lightbake-chromium-'));
  const context = await chromium.launchPersistentContext(profile, {
    executablePath: process.env.LIGHTBAKE_CHROMIUM || '/usr/bin/chromium',
    headless: true,
    viewport: size,
    deviceScaleFactor: 1,
    args: [
      '--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
      '--disable-background-networking', '--disable-component-update', '--disable-sync',
      // WebGL on the CPU (SwiftShader): there is no GPU in CI.
      '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
    ],
  });
  const errors = [];
  try {
    const page = context.pages()[0] || await context.newPage();
    page.on('pageerror', (e) => errors.push(`page error: ${e.message}`));
    page.on('console', (m) => { if (m.type() === 'error') errors.push(`console: ${m.text()}`); });
    // Playwright's 30 s default is short on a loaded 2-core machine (software WebGL).
    page.setDefaultTimeout(120000);
    await page.goto(url);
    await page.evaluate(() => window.lightbake.ready);
    const rgb = await page.evaluate(([w, h]) => {
      window.lightbake.setExposure(0);
      window.lightbake.setCamera(0);
      window.lightbake.setView('lit');
      return window.lightbake.readLinear(w, h);
    }, [+readSide, +readSide]);
    fs.writeFileSync(path.join(out, 'lit.json'), JSON.stringify({ side: +readSide, rgb }));
    for (const view of views) {
      // The canvas alone (not the panel, whose text changes with the view too).
      const png = await page.evaluate((v) => {
        window.lightbake.setView(v);
        return document.getElementById('canvas').toDataURL('image/png');
      }, view);
      fs.writeFileSync(path.join(out, `${view}.png`), Buffer.from(png.split(',')[1], 'base64'));
    }
    if (process.env.LIGHTBAKE_PROBE_SPOTS) {
      const spots = JSON.parse(process.env.LIGHTBAKE_PROBE_SPOTS);
      const shots = await page.evaluate(() => {
        const lb = window.lightbake;
        if (!lb.probes.available()) throw new Error('the page found no probes');
        lb.setExposure(0);
        lb.setCamera(0);
        lb.setView('lit');
        const canvas = document.getElementById('canvas');
        lb.probes.showProbes(false);
        const off = canvas.toDataURL('image/png');
        lb.probes.showProbes(true);
        const on = canvas.toDataURL('image/png');
        lb.probes.showProbes(false);
        return [off, on];
      });
      shots.forEach((png, k) => fs.writeFileSync(path.join(out, k ? 'probes_on.png' : 'probes_off.png'),
        Buffer.from(png.split(',')[1], 'base64')));
      // An odd side: the centre pixel looks straight at the sphere's centre.
      const side = 33;
      const result = [];
      for (const spot of spots) {
        result.push(await page.evaluate(async ([spot, side]) => {
          const lb = window.lightbake;
          const sh = await lb.probes.moveSphere(spot.sphere);
          lb.probes.lookAtSphere(spot.eye);
          const rgb = lb.readLinear(side, side);
          const c = ((side - 1) / 2) * side + (side - 1) / 2;
          return { sh, centre: rgb.slice(3 * c, 3 * c + 3) };
        }, [spot, side]));
      }
      fs.writeFileSync(path.join(out, 'probes.json'), JSON.stringify({ spots: result }));
    }
  } finally {
    await context.close();
    fs.rmSync(profile, { recursive: true, force: true });
  }
  if (errors.length) throw new Error(errors.join('\n'));
}

main().catch((e) => { console.error(e); process.exit(1); });

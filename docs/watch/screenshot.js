// Headless screenshots of the Rerun web viewer and TensorBoard (docs/watch/README.md).
// npm install playwright-core; node screenshot.js <url> <out.png> <seconds to wait> [tag filter]
const { chromium } = require('playwright-core');
(async () => {
  const [url, out, waitS, tags] = process.argv.slice(2);
  const browser = await chromium.launch({
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
    args: ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader'],
  });
  const page = await browser.newPage({ viewport: { width: 1600, height: Number(process.env.HEIGHT || 900) } });
  await page.goto(url);
  await page.waitForTimeout(1000 * Number(waitS || 40));
  if (tags) {
    // TensorBoard's tag filter, then close its suggestion list.
    await page.fill('input[placeholder="Filter tags (regex)"]', tags);
    await page.keyboard.press('Escape');
    await page.mouse.click(700, 20);
    await page.waitForTimeout(8000);
  }
  await page.screenshot({ path: out });
  await browser.close();
})();

import { openReport } from "./test/browser.mjs";
const { browser, page } = await openReport(process.argv[2]);
try {
  const r = await page.evaluate(() => { let out_tris;
    const X = window.__x, T = X.THREE;
    const gl = X.renderer.getContext();
    const px = new Uint8Array(4);
    const R = () => X.renderer.render(X.scene, X.camera);
    const time = (k = 4) => { R(); gl.readPixels(0,0,1,1,gl.RGBA,gl.UNSIGNED_BYTE,px); const t0 = performance.now(); for (let i = 0; i < k; i++) { R(); gl.readPixels(0,0,1,1,gl.RGBA,gl.UNSIGNED_BYTE,px); } return (performance.now() - t0) / k; };
    const fm = X.faceAfter.material, bm = X.skullAfter.material;
    const lamF = new T.MeshLambertMaterial({ vertexColors: true, side: T.DoubleSide, transparent: true, opacity: 0.55, depthWrite: false, forceSinglePass: true });
    const lamB = new T.MeshLambertMaterial({ color: 0xeeeadd, side: T.DoubleSide });
    const basF = new T.MeshBasicMaterial({ vertexColors: true, side: T.DoubleSide, transparent: true, opacity: 0.55, depthWrite: false, forceSinglePass: true });
    const basB = new T.MeshBasicMaterial({ color: 0xeeeadd, side: T.DoubleSide });
    const reset = () => { X.faceAfter.material = fm; X.skullAfter.material = bm; fm.forceSinglePass = false; bm.side = T.DoubleSide; lamB.side = T.DoubleSide; X.renderer.setPixelRatio(1); basB.side = T.DoubleSide; X.skullAfter.visible = true; X.faceAfter.visible = true; };
    const sortIdx = (g) => { const ix = g.index.array; const t = []; for (let i = 0; i < ix.length; i += 3) t.push([Math.min(ix[i], ix[i+1], ix[i+2]), ix[i], ix[i+1], ix[i+2]]); t.sort((a, b) => a[0] - b[0]); const o = new Uint32Array(ix.length); t.forEach((q, i) => { o[3*i] = q[1]; o[3*i+1] = q[2]; o[3*i+2] = q[3]; }); return o; };
    const skIx = X.skullAfter.geometry.index.array.slice(), skSorted = sortIdx(X.skullAfter.geometry);
    const setSk = (a) => { X.skullAfter.geometry.index.array.set(a); X.skullAfter.geometry.index.needsUpdate = true; };
    const tiny = () => { X.faceAfter.visible = false; X.skullAfter.material = basB; X.renderer.setPixelRatio(0.05); };
    const cfg = {
      sk_tiny: () => { tiny(); setSk(skIx); },
      sk_tiny_sorted: () => { tiny(); setSk(skSorted); },
      sk_tiny_front: () => { tiny(); setSk(skIx); basB.side = T.FrontSide; },
      sk_tiny_hidden: () => { tiny(); X.skullAfter.visible = false; },
      sk_full_basic: () => { X.faceAfter.visible = false; X.skullAfter.material = basB; setSk(skIx);},
      sk_full_basic_front: () => { X.faceAfter.visible = false; X.skullAfter.material = basB; basB.side = T.FrontSide; setSk(skIx); },
      sk_full_std: () => { X.faceAfter.visible = false; setSk(skIx);},
      sk_full_std_front: () => { X.faceAfter.visible = false; bm.side = T.FrontSide; setSk(skIx);},
    };
    out_tris = [X.faceAfter.geometry.index.count / 3, X.skullAfter.geometry.index.count / 3];
    const res = {tris: out_tris};
    for (let round = 0; round < 4; round++)
      for (const [k, f] of Object.entries(cfg)) { reset(); f(); (res[k] ||= []).push(time()); }
    reset();
    const o = {};
    for (const [k, v] of Object.entries(res)) o[k] = v.map((x) => x.toFixed(0)).join(" ") + ' min ' + Math.min(...v).toFixed(1);
    return o;
  });
  console.log(JSON.stringify(r, null, 1));
} finally { await browser.close(); }

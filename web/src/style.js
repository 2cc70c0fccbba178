// The page's style sheet, injected by the bundle (so that layout changes need no Rust rebuild).
// Screen: controls and tables on the left, the picture on the right with its toolbar, labels,
// colour legend and the profile tracing over it. Print: one page — the picture and the tracing
// side by side, the tables below, every control hidden.
export const STYLE = `
html,body{margin:0;height:100%;font:14px/1.45 system-ui,sans-serif;color:#1d1d1d;background:#fff}
body{display:flex}
#side{width:330px;flex:none;overflow:auto;padding:10px 14px;box-sizing:border-box;border-right:1px solid #ccc}
#main{flex:1;display:flex;min-width:0}
#view{flex:1;position:relative;min-width:0;overflow:hidden;background:#f4f4f4}
#view canvas{display:block;width:100%;height:100%}
#view canvas:focus-visible{outline:3px solid #1a5fb4;outline-offset:-3px}
h1{font-size:18px;margin:0 0 2px}
h2{font-size:15px;margin:16px 0 4px}
h3{font-size:14px;margin:8px 0 2px}
.model,.frame-note{margin:0;color:#444;font-size:13px}
fieldset{margin:8px 0;border:1px solid #bbb;border-radius:4px}
fieldset label{display:block;padding:1px 0}
button{font:inherit;padding:3px 9px;border:1px solid #888;border-radius:4px;background:#fff;color:#1d1d1d;cursor:pointer}
button[aria-pressed=true]{background:#1a5fb4;border-color:#1a5fb4;color:#fff}
button:focus-visible,input:focus-visible{outline:3px solid #e5a50a;outline-offset:1px}
label.slider{display:grid;grid-template-columns:64px 1fr 64px;align-items:center}
label.slider.tissue{grid-template-columns:82px 1fr 46px}
p.tissue-bound{font-size:12.5px;color:#174;margin:4px 0}
.label,.why{font-weight:bold;color:#a40}
table{border-collapse:collapse;margin:2px 0 6px}
caption{text-align:left;font-weight:600;padding:2px 0;font-size:14px}
th,td{padding:2px 8px 2px 0;text-align:left;vertical-align:top}
td.num{text-align:right;font-variant-numeric:tabular-nums}
thead th{border-bottom:1px solid #999;font-weight:600}
tbody th{font-weight:normal;color:#333}
tbody tr:nth-child(even){background:#f3f3f3}
ul.warnings{padding-left:18px;color:#a40}
table.clinic tr.outside td{color:#b00;font-weight:bold}
table.clinic tr.inside td:last-child{color:#070}
table.clinic tr.consistent td:last-child{color:#a60}
table.sensitivity td.top{font-weight:bold}
p.certified{font-size:12.5px;color:#174}
.clinic-reading,.hint{font-size:12.5px;color:#444}
#toolbar{position:absolute;top:6px;left:6px;right:6px;display:flex;flex-wrap:wrap;gap:6px;font-size:13px}
#toolbar button{padding:2px 7px}
#toolbar [role=group]{display:flex;gap:3px;background:rgba(255,255,255,.88);padding:3px;border-radius:6px}
#labels{position:absolute;inset:0;pointer-events:none}
.lm{position:absolute;left:0;top:0;font:600 12px/1 system-ui,sans-serif;color:#111;background:rgba(255,255,255,.82);
 padding:2px 3px;border-radius:3px;white-space:nowrap;will-change:transform}
.lm.bone{color:#123b8c}
#legend{position:absolute;left:8px;bottom:8px;background:rgba(255,255,255,.9);padding:5px 8px;border-radius:6px;font-size:12.5px;width:230px}
#legend .ramp{height:12px;border:1px solid #777;margin:3px 0 0}
#legend .ticks{display:flex;justify-content:space-between;font-variant-numeric:tabular-nums}
#profile{flex:none;width:260px;border-left:1px solid #ccc;padding:8px;box-sizing:border-box;overflow:auto}
#profile h2{margin:0;font-size:13.5px}
#profile svg{display:block;width:100%;height:auto;max-height:calc(100vh - 90px)}
#profile .before{fill:none;stroke:#777;stroke-width:1.6;stroke-dasharray:4 3;vector-effect:non-scaling-stroke}
#profile .after{fill:none;stroke:#c01c28;stroke-width:2;vector-effect:non-scaling-stroke}
#profile .bar{stroke:#333;stroke-width:1.5;vector-effect:non-scaling-stroke}
#profile .key{font-size:12px;display:flex;gap:12px}
#profile .key span::before{content:"";display:inline-block;width:18px;height:0;margin:0 4px 3px 0;border-top:2px solid #c01c28}
#profile .key span.b::before{border-top:2px dashed #777}
@media print{
 @page{size:A4 portrait;margin:9mm}
 html,body{height:auto;font-size:10px;background:#fff}
 body{display:flex;flex-direction:column}
 #side{display:contents}
 #side>:not(h1):not(.model):not(#summary),#toolbar,.noprint{display:none!important}
 h1{font-size:15px;order:0}
 .model{order:0}
 #main{order:1;display:flex;gap:4mm;align-items:flex-start;margin:2mm 0}
 #view canvas{outline:none!important}
 #view{flex:none;width:var(--view-w);height:var(--view-h);zoom:var(--print-zoom);border:1px solid #bbb}
 #profile{width:64mm;border:1px solid #bbb}
 #profile svg{height:108mm;max-height:none}
 #summary{order:2;columns:2;column-gap:6mm;font-size:9.5px}
 #summary table{break-inside:avoid;font-size:9.5px;width:100%}
 #summary caption{font-size:10.5px}
 th,td{padding:0 5px 0 0}
}
`;

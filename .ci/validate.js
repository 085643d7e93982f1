// Validates a .gltf/.glb with the Khronos glTF-Validator; exits 1 when it reports errors.
// Usage: node .ci/validate.js <file>   (needs `npm install gltf-validator`, e.g. NODE_PATH)
const v = require('gltf-validator');
const fs = require('fs');
const path = require('path');
const f = process.argv[2];
v.validateBytes(new Uint8Array(fs.readFileSync(f)), {
    uri: f,
    externalResourceFunction: (u) => new Promise((res, rej) => {
        try {
            res(new Uint8Array(fs.readFileSync(path.join(path.dirname(f), decodeURIComponent(u)))));
        } catch (e) {
            rej(e.toString());
        }
    }),
}).then((r) => {
    console.log(JSON.stringify(r.issues, null, 1));
    process.exit(r.issues.numErrors > 0 ? 1 : 0);
}, (e) => {
    console.error(e.toString());
    process.exit(2);
});

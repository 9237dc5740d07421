// An independent OPC UA client for the gateway's tests: node-opcua, driven by one JSON request.
//
//   node client.mjs '<json>'        (or the JSON on stdin when no argument is given)
//
// prints ONE JSON object on stdout and exits 0 when every step went through, 1 when not
// (the object then has "error": {"message", "statusCode"}: the status code's name where
// the failure has one). Everything node-opcua itself logs goes to stderr.
//
// The request:
//
//   {
//     "endpoint": "opc.tcp://127.0.0.1:4840",
//     "pki": "/tmp/.../node-pki",        the client's PKI folder (its own certificate, made
//                                        there on first use; the server's, accepted as it comes)
//     "securityMode": "None" | "Sign" | "SignAndEncrypt",              (default "None")
//     "securityPolicy": "Basic256Sha256" | "None",     (default: None for mode None, else
//                                                       Basic256Sha256)
//     "user": "operator", "password": "...",          (no user: an anonymous session)
//     "timeoutMs": 30000,                              the whole run's deadline
//     "steps": [ {"op": ..., ...}, ... ]               in order, in one session
//   }
//
// Without "endpoint" it only makes the client's certificate in "pki" (an RSA key: the slow
// part of a first run) and answers {"ok": true, "certificate": path, "steps": []}.
//
// A node id is node-opcua's text ("ns=2;s=hall/Drive1", "i=85") or "nsu=<uri>;s=..." with
// the namespace's URI (resolved through the server's NamespaceArray). Each step's result is
// in "steps", in order ({"op": ..., ...}):
//
//   {"op": "namespaces"}                   -> {"namespaces": [uri, ...]}
//   {"op": "endpoints"}                    -> {"endpoints": [{securityMode, securityPolicy,
//                                              userTokens: [type names]}]}
//   {"op": "browse", "nodeId", "depth": 1} -> {"node": {nodeId, children: [{nodeId,
//                                              browseName, nodeClass, referenceType,
//                                              typeDefinition, children}, ...]}}: the forward
//                                              hierarchical references, "depth" levels down
//                                              (a level's nodes in one Browse request);
//                                              browseName is "namespaceIndex:name"
//   {"op": "read", "nodeIds": [...], "attribute": "Value"}
//                                          -> {"values": [dataValue, ...]}
//   {"op": "properties", "nodeId", "names": ["EngineeringUnits", "EURange"]}
//                                          -> {"properties": {name: dataValue}} (a property
//                                              not found: {"statusCode": "BadNoMatch"...})
//   {"op": "call", "objectId", "methodId", "inputArguments": [{"dataType": "Double",
//    "value": 50}]}                        -> {"statusCode", "inputArgumentResults": [names],
//                                              "outputArguments": [{dataType, value}]}
//   {"op": "write", "nodeId", "dataType": "Double", "value": 1.5}
//                                          -> {"statusCode"}
//   {"op": "subscribe", "id": "f", "nodeId", "samplingInterval": 0, "publishingInterval": 50,
//    "until": {...}, "timeoutMs": 10000, "background": false}
//                                          -> {"notifications": [{statusCode, value, dataType,
//                                              sourceTimestamp, serverTimestamp, receivedAt}],
//                                              "reason": "until" | "count" | "timeout"}
//       "until": {"count": N} (N notifications), and/or a condition on one notification:
//       {"gt": x, "ge": x, "lt": x, "le": x, "eq": v, "ne": v, "status": "Good"} (all of
//       those given must hold). With "background": true the step returns {"started": true}
//       once the monitored item exists, and a later {"op": "wait", "id": "f"} returns the
//       notifications; the steps in between run meanwhile.
//   {"op": "wait", "id": "f"}              -> as "subscribe"
//   {"op": "subscribe", "nodeId": "i=2253", "events": ["SourceName", "Message", ...], ...}
//                                          -> events instead of values: the item monitors
//                                              the node's EventNotifier with an event filter
//                                              selecting those fields (browse names from
//                                              BaseEventType's, a subtype's by their name
//                                              too); each notification is {field: value},
//                                              "until": {"count": N} only
//
// A dataValue: {statusCode, value, dataType, sourceTimestamp, serverTimestamp} (the status
// code's and the variant's data type's names). A value: numbers, strings, booleans as such; NaN and infinities as the strings "NaN",
// "Infinity", "-Infinity"; 64-bit integers as numbers; dates as ISO text; structures
// (EUInformation, Range, LocalizedText...) as objects of their fields. A written or passed
// Double / Float given as one of those strings is that number. Timestamps are ISO text
// (milliseconds; null when the server sent none); "receivedAt" is this process's clock.

import fs from "node:fs";
import util from "node:util";

// node-opcua prints warnings with console.log at import time: keep stdout for the result.
const writeOut = process.stdout.write.bind(process.stdout);
for (const name of ["log", "info", "warn", "debug", "error", "trace"]) {
    console[name] = (...args) => process.stderr.write(`${util.format(...args)}\n`);
}

const opcua = await import("node-opcua-client");
const { OPCUACertificateManager } = await import("node-opcua-certificate-manager");
const {
    AttributeIds,
    BrowseDirection,
    ClientMonitoredItem,
    ClientSubscription,
    DataType,
    MessageSecurityMode,
    NodeClass,
    NodeId,
    ExpandedNodeId,
    OPCUAClient,
    SecurityPolicy,
    TimestampsToReturn,
    UserTokenType,
    Variant,
    VariantArrayType,
    coerceNodeId,
    constructEventFilter,
    makeBrowsePath,
} = opcua;

const FLOATS = new Set(["Double", "Float"]);

class StepError extends Error {
    constructor(message, statusCode) {
        super(message);
        this.statusCode = statusCode;
    }
}

function statusName(statusCode) {
    if (statusCode === null || statusCode === undefined) return null;
    return statusCode.name ?? String(statusCode);
}

function errorOf(err) {
    const message = err?.message ?? String(err);
    let code = err?.statusCode ? statusName(err.statusCode) : null;
    code ??= statusName(err?.response?.responseHeader?.serviceResult);
    if (!code) {
        const found = /\b(Bad[A-Za-z]+|Uncertain[A-Za-z]+)\b/.exec(message);
        code = found ? found[1] : null;
    }
    return { message: message.trim(), statusCode: code };
}

function plain(value) {
    if (value === null || value === undefined) return null;
    if (typeof value === "number") return Number.isFinite(value) ? value : String(value);
    if (typeof value === "bigint") return Number(value);
    if (typeof value === "string" || typeof value === "boolean") return value;
    if (value instanceof Date) return Number.isNaN(value.getTime()) ? null : value.toISOString();
    if (Buffer.isBuffer(value)) return value.toString("base64");
    if (Array.isArray(value) || ArrayBuffer.isView(value)) return Array.from(value, plain);
    if (value instanceof NodeId || value instanceof ExpandedNodeId) return value.toString();
    const schema = value.schema;
    if (schema && Array.isArray(schema.fields)) {
        const out = {};
        for (const field of allFields(schema)) out[field.name] = plain(value[field.name]);
        return out;
    }
    if (typeof value.toJSON === "function") return plain(value.toJSON());
    const out = {};
    for (const [key, item] of Object.entries(value)) out[key] = plain(item);
    return out;
}

function allFields(schema) {
    const base = schema._baseSchema && schema._baseSchema.fields ? allFields(schema._baseSchema) : [];
    return [...base, ...schema.fields];
}

function variantValue(variant) {
    if (!variant) return null;
    const type = DataType[variant.dataType];
    const value = variant.value;
    if ((type === "UInt64" || type === "Int64") && Array.isArray(value) && value.length === 2
        && variant.arrayType === VariantArrayType.Scalar) {
        return value[0] * 2 ** 32 + value[1];
    }
    return plain(value);
}

function iso(date) {
    return date instanceof Date && !Number.isNaN(date.getTime()) ? date.toISOString() : null;
}

function dataValue(dv, receivedAt) {
    const out = {
        statusCode: statusName(dv.statusCode),
        value: variantValue(dv.value),
        dataType: dv.value ? DataType[dv.value.dataType] : null,
        sourceTimestamp: iso(dv.sourceTimestamp),
        serverTimestamp: iso(dv.serverTimestamp),
    };
    if (receivedAt !== undefined) out.receivedAt = receivedAt;
    return out;
}

function makeVariant(argument) {
    const typeName = argument.dataType;
    const dataType = DataType[typeName];
    if (dataType === undefined || typeof dataType !== "number") {
        throw new StepError(`unknown data type ${typeName}`, null);
    }
    let value = argument.value;
    if (FLOATS.has(typeName) && typeof value === "string") value = Number(value);
    if (Array.isArray(value)) {
        if (FLOATS.has(typeName)) value = value.map((v) => (typeof v === "string" ? Number(v) : v));
        return new Variant({ dataType, arrayType: VariantArrayType.Array, value });
    }
    return new Variant({ dataType, value });
}

class Runner {
    constructor(request) {
        this.request = request;
        this.session = null;
        this.namespaces = null;
        this.subscriptions = new Map();
    }

    async nodeId(text) {
        if (typeof text !== "string") throw new StepError(`a node id must be text: ${text}`, null);
        const found = /^nsu=([^;]+);(.*)$/.exec(text);
        if (!found) return coerceNodeId(text);
        const namespaces = await this.readNamespaces();
        const index = namespaces.indexOf(found[1]);
        if (index < 0) throw new StepError(`no namespace ${found[1]} on the server`, "BadNodeIdUnknown");
        return coerceNodeId(`ns=${index};${found[2]}`);
    }

    async readNamespaces() {
        if (this.namespaces === null) {
            const dv = await this.session.read({ nodeId: "i=2255", attributeId: AttributeIds.Value });
            this.namespaces = dv.value.value;
        }
        return this.namespaces;
    }

    async browseAll(nodeIds) {
        // One Browse request per 100 nodes, each result's continuation points followed.
        const results = [];
        for (let start = 0; start < nodeIds.length; start += 100) {
            const batch = nodeIds.slice(start, start + 100).map((nodeId) => ({
                nodeId,
                browseDirection: BrowseDirection.Forward,
                referenceTypeId: "HierarchicalReferences",
                includeSubtypes: true,
                nodeClassMask: 0,
                resultMask: 0x3f,
            }));
            results.push(...(await this.session.browse(batch)));
        }
        const references = [];
        for (const [index, result] of results.entries()) {
            if (result.statusCode.isNotGood()) {
                const name = result.statusCode.name;
                throw new StepError(`browse ${nodeIds[index].toString()}: ${name}`, name);
            }
            const found = [...(result.references ?? [])];
            let continuationPoint = result.continuationPoint;
            while (continuationPoint && continuationPoint.length) {
                const next = await this.session.browseNext(continuationPoint, false);
                found.push(...(next.references ?? []));
                continuationPoint = next.continuationPoint;
            }
            references.push(found);
        }
        return references;
    }

    async browseTree(nodeId, depth) {
        // Level by level: every node of a level in one Browse request.
        const root = { nodeId: nodeId.toString() };
        let level = [[root, nodeId]];
        for (let remaining = depth; remaining > 0 && level.length; remaining--) {
            const references = await this.browseAll(level.map(([, id]) => id));
            const next = [];
            for (const [index, [node]] of level.entries()) {
                node.children = references[index].map((reference) => {
                    const child = {
                        nodeId: reference.nodeId.toString(),
                        browseName: `${reference.browseName.namespaceIndex}:${reference.browseName.name}`,
                        nodeClass: NodeClass[reference.nodeClass],
                        referenceType: reference.referenceTypeId.toString(),
                        typeDefinition: reference.typeDefinition?.toString() ?? null,
                    };
                    next.push([child, coerceNodeId(child.nodeId)]);
                    return child;
                });
            }
            level = next;
        }
        return root;
    }

    async subscribe(step) {
        const nodeId = await this.nodeId(step.nodeId);
        const subscription = ClientSubscription.create(this.session, {
            requestedPublishingInterval: step.publishingInterval ?? 50,
            requestedLifetimeCount: 600,
            requestedMaxKeepAliveCount: 20,
            maxNotificationsPerPublish: 0,
            publishingEnabled: true,
            priority: 1,
        });
        await new Promise((resolve, reject) => {
            subscription.once("started", resolve);
            subscription.once("internal_error", reject);
        });
        const notifications = [];
        const until = step.until ?? {};
        const condition = ["gt", "ge", "lt", "le", "eq", "ne", "status"].some((key) => key in until);
        let finish;
        const done = new Promise((resolve) => {
            finish = resolve;
        });
        const events = step.events ?? null;
        const item = ClientMonitoredItem.create(
            subscription,
            { nodeId, attributeId: events ? AttributeIds.EventNotifier : AttributeIds[step.attribute ?? "Value"] },
            {
                samplingInterval: step.samplingInterval ?? 0,
                discardOldest: true,
                queueSize: step.queueSize ?? 100,
                ...(events ? { filter: constructEventFilter(events) } : {}),
            },
            TimestampsToReturn.Both,
        );
        item.on("changed", (dv) => {
            // An event's fields come as an array of variants, in the filter's order.
            const notification = events
                ? Object.fromEntries(events.map((name, i) => [name, variantValue(dv[i])]))
                : dataValue(dv, new Date().toISOString());
            notifications.push(notification);
            if (condition && holds(until, notification)) finish("until");
            else if (until.count !== undefined && notifications.length >= until.count) finish("count");
        });
        item.on("err", (message) => finish({ error: new StepError(`monitored item: ${message}`, null) }));
        await new Promise((resolve, reject) => {
            item.once("initialized", resolve);
            item.once("err", (message) => reject(new StepError(`monitored item: ${message}`, null)));
        });
        const timer = setTimeout(() => finish("timeout"), step.timeoutMs ?? 10000);
        const outcome = (async () => {
            const reason = await done;
            clearTimeout(timer);
            await subscription.terminate().catch(() => undefined);
            if (typeof reason === "object") throw reason.error;
            return { notifications: [...notifications], reason };
        })();
        outcome.catch(() => undefined); // awaited by the wait step; no unhandled rejection meanwhile
        return { outcome }; // wrapped: an async function returning a promise would wait for it
    }

    async step(step) {
        const session = this.session;
        switch (step.op) {
            case "namespaces":
                this.namespaces = null;
                return { namespaces: await this.readNamespaces() };
            case "endpoints": {
                const endpoints = await this.client.getEndpoints();
                return {
                    endpoints: endpoints.map((e) => ({
                        securityMode: MessageSecurityMode[e.securityMode],
                        securityPolicy: e.securityPolicyUri.split("#").pop(),
                        userTokens: (e.userIdentityTokens ?? []).map((t) => UserTokenType[t.tokenType]),
                    })),
                };
            }
            case "browse": {
                return { node: await this.browseTree(await this.nodeId(step.nodeId), step.depth ?? 1) };
            }
            case "read": {
                const nodesToRead = [];
                for (const text of step.nodeIds) {
                    nodesToRead.push({ nodeId: await this.nodeId(text), attributeId: AttributeIds[step.attribute ?? "Value"] });
                }
                const values = await session.read(nodesToRead, step.maxAge ?? 0);
                return { values: values.map((dv) => dataValue(dv)) };
            }
            case "properties": {
                const nodeId = await this.nodeId(step.nodeId);
                const names = step.names ?? ["EngineeringUnits", "EURange"];
                const paths = names.map((name) => makeBrowsePath(nodeId, `.0:${name}`));
                const results = await session.translateBrowsePath(paths);
                const properties = {};
                for (const [index, name] of names.entries()) {
                    const result = results[index];
                    if (result.statusCode.isNotGood() || !result.targets?.length) {
                        properties[name] = { statusCode: statusName(result.statusCode), value: null };
                        continue;
                    }
                    const target = coerceNodeId(result.targets[0].targetId.toString());
                    const dv = await session.read({ nodeId: target, attributeId: AttributeIds.Value });
                    properties[name] = { nodeId: target.toString(), ...dataValue(dv) };
                }
                return { properties };
            }
            case "call": {
                const result = await session.call({
                    objectId: await this.nodeId(step.objectId),
                    methodId: await this.nodeId(step.methodId),
                    inputArguments: (step.inputArguments ?? []).map(makeVariant),
                });
                return {
                    statusCode: statusName(result.statusCode),
                    inputArgumentResults: (result.inputArgumentResults ?? []).map(statusName),
                    outputArguments: (result.outputArguments ?? []).map((v) => ({
                        dataType: DataType[v.dataType],
                        value: variantValue(v),
                    })),
                };
            }
            case "write": {
                const statusCode = await session.write({
                    nodeId: await this.nodeId(step.nodeId),
                    attributeId: AttributeIds[step.attribute ?? "Value"],
                    value: { value: makeVariant(step) },
                });
                return { statusCode: statusName(statusCode) };
            }
            case "subscribe": {
                const { outcome } = await this.subscribe(step);
                if (step.background) {
                    this.subscriptions.set(step.id ?? "default", outcome);
                    return { started: true };
                }
                return await outcome;
            }
            case "wait": {
                const outcome = this.subscriptions.get(step.id ?? "default");
                if (!outcome) throw new StepError(`no background subscription ${step.id}`, null);
                this.subscriptions.delete(step.id ?? "default");
                return await outcome;
            }
            default:
                throw new StepError(`unknown op ${step.op}`, null);
        }
    }

    async run() {
        const request = this.request;
        const mode = request.securityMode ?? "None";
        if (!(mode in MessageSecurityMode) || mode === "Invalid") {
            throw new StepError(`unknown securityMode ${mode}`, null);
        }
        const policy = request.securityPolicy ?? (mode === "None" ? "None" : "Basic256Sha256");
        if (!request.pki) throw new StepError("the request names no pki folder", null);
        const certificateManager = new OPCUACertificateManager({
            rootFolder: request.pki,
            automaticallyAcceptUnknownCertificate: true,
        });
        await certificateManager.initialize();
        this.certificateManager = certificateManager;
        const client = OPCUAClient.create({
            applicationName: "sj300-node-opcua-test",
            securityMode: MessageSecurityMode[mode],
            securityPolicy: SecurityPolicy[policy],
            endpointMustExist: false,
            keepSessionAlive: false,
            requestedSessionTimeout: 60000,
            connectionStrategy: { maxRetry: 0, initialDelay: 100, maxDelay: 200 },
            clientCertificateManager: certificateManager,
        });
        this.client = client;
        if (!request.endpoint) {
            // No endpoint: make the client's certificate (the slow part: an RSA key) and stop.
            try {
                await client.createDefaultCertificate();
                this.certificate = client.certificateFile;
            } finally {
                await certificateManager.dispose().catch(() => undefined);
            }
            return;
        }
        await client.connect(request.endpoint);
        try {
            const identity = request.user
                ? { type: UserTokenType.UserName, userName: request.user, password: request.password ?? "" }
                : { type: UserTokenType.Anonymous };
            this.session = await client.createSession(identity);
            try {
                for (const step of request.steps ?? []) {
                    const result = { op: step.op, ...(await this.step(step)) };
                    this.results.push(result);
                }
            } finally {
                await this.session.close().catch(() => undefined);
            }
        } finally {
            await client.disconnect().catch(() => undefined);
            await certificateManager.dispose().catch(() => undefined);
        }
    }
}

function holds(until, notification) {
    const value = notification.value;
    if ("status" in until && notification.statusCode !== until.status) return false;
    const numeric = typeof value === "number";
    if ("gt" in until && !(numeric && value > until.gt)) return false;
    if ("ge" in until && !(numeric && value >= until.ge)) return false;
    if ("lt" in until && !(numeric && value < until.lt)) return false;
    if ("le" in until && !(numeric && value <= until.le)) return false;
    if ("eq" in until && !util.isDeepStrictEqual(value, until.eq)) return false;
    if ("ne" in until && util.isDeepStrictEqual(value, until.ne)) return false;
    return true;
}

async function readRequest() {
    if (process.argv.length > 2) return JSON.parse(process.argv[2]);
    return JSON.parse(fs.readFileSync(0, "utf8"));
}

async function main() {
    let runner = null;
    let output;
    try {
        const request = await readRequest();
        runner = new Runner(request);
        runner.results = [];
        const deadline = request.timeoutMs ?? 30000;
        let timer;
        const expired = new Promise((_, reject) => {
            timer = setTimeout(() => reject(new StepError(`no result within ${deadline} ms`, "BadTimeout")), deadline);
        });
        try {
            await Promise.race([runner.run(), expired]);
        } finally {
            clearTimeout(timer);
        }
        output = { ok: true, steps: runner.results };
        if (runner.certificate) output.certificate = runner.certificate;
    } catch (err) {
        output = { ok: false, error: errorOf(err), steps: runner?.results ?? [] };
    }
    writeOut(`${JSON.stringify(output)}\n`, () => process.exit(output.ok ? 0 : 1));
}

await main();

// How Foxglove and Lichtblick decode a channel (their parseChannel): protobuf against the schema's
// FileDescriptorSet (@mcap/support protobufFromBinaryDescriptor, protobufjs), json by JSON.parse; any other
// encoding is one these viewers cannot show. Returns {deserialize(bytes) -> object}; throws naming the encoding.
import * as mcapSupport from "@mcap/support";

const { protobufFromBinaryDescriptor } = mcapSupport;
const textDecoder = new TextDecoder();

export function channelParser(messageEncoding, schemaName, schemaEncoding, schemaData) {
  if (messageEncoding === "protobuf") {
    if (schemaEncoding !== "protobuf") throw new Error(`protobuf message with a ${schemaEncoding} schema`);
    const root = protobufFromBinaryDescriptor(schemaData);
    const type = root.lookupType(schemaName);
    return { deserialize: (bytes) => type.toObject(type.decode(bytes), { defaults: true }) };
  }
  if (messageEncoding === "json") {
    if (schemaEncoding !== "jsonschema" && schemaEncoding !== "") {
      throw new Error(`json message with a ${schemaEncoding} schema`);
    }
    if (schemaEncoding === "jsonschema") JSON.parse(textDecoder.decode(schemaData));
    return { deserialize: (bytes) => JSON.parse(textDecoder.decode(bytes)) };
  }
  throw new Error(`message encoding ${JSON.stringify(messageEncoding)} is not one the viewers decode`);
}
